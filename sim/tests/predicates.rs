//! Predicates on hand-placed scenes: bowl on plate, cheese in basket, drawer open/closed, stove on/off.

use sim::mujoco::Data;
use sim::predicates::Predicates;
use sim::scene::{InstanceSpec, RegionSpec, Scene, SceneSpec};

fn spec() -> SceneSpec {
    let region = |name: &str, target: &str, r: Option<[f64; 4]>| RegionSpec {
        name: name.into(),
        target: target.into(),
        ranges: r.into_iter().collect(),
        yaw: [0.0, 0.0],
        rgba: [0.0, 0.0, 1.0, 0.0],
    };
    let inst = |n: &str, c: &str| InstanceSpec {
        name: n.into(),
        category: c.into(),
    };
    SceneSpec {
        problem_class: "libero_kitchen_tabletop_manipulation".into(),
        regions: vec![
            region(
                "the_center",
                "kitchen_table",
                Some([-0.10, -0.17, 0.25, 0.20]),
            ),
            region("contain_region", "basket_1", None),
            region("top_region", "wooden_cabinet_1", None),
            region("cook_region", "flat_stove_1", None),
        ],
        fixtures: vec![
            inst("kitchen_table", "kitchen_table"),
            inst("wooden_cabinet_1", "wooden_cabinet"),
            inst("flat_stove_1", "flat_stove"),
        ],
        objects: vec![
            inst("akita_black_bowl_1", "akita_black_bowl"),
            inst("plate_1", "plate"),
            inst("cream_cheese_1", "cream_cheese"),
            inst("basket_1", "basket"),
        ],
        init: vec![],
    }
}

struct Fixture {
    scene: Scene,
    data: Data,
}

impl Fixture {
    fn new() -> Fixture {
        let scene = Scene::build(spec()).unwrap();
        let mut data = Data::new(scene.model.clone()).unwrap();
        // Robot folded at its init pose; fixtures at fixed poses; objects parked.
        let init = sim::robot::INIT_QPOS;
        data.qpos_mut()[..7].copy_from_slice(&init);
        let mut f = Fixture { scene, data };
        f.fixture(
            "wooden_cabinet_1",
            [0.0, -0.40, 0.905],
            std::f64::consts::PI,
        );
        f.fixture("flat_stove_1", [-0.3, 0.35, 0.905], 0.0);
        for (k, name) in [
            "akita_black_bowl_1",
            "plate_1",
            "cream_cheese_1",
            "basket_1",
        ]
        .iter()
        .enumerate()
        {
            f.put(name, [0.3, -0.3 + 0.2 * k as f64, 0.905]);
        }
        f
    }

    fn fixture(&mut self, name: &str, pos: [f64; 3], yaw: f64) {
        let i = self.scene.instance(name).unwrap();
        let m = self.scene.instances[i].mocap.unwrap();
        self.data.mocap_pos_mut()[3 * m..3 * m + 3].copy_from_slice(&pos);
        self.data.mocap_quat_mut()[4 * m..4 * m + 4].copy_from_slice(&sim::assets::yaw_quat(yaw));
    }

    fn put(&mut self, name: &str, pos: [f64; 3]) {
        let i = self.scene.instance(name).unwrap();
        let a = self.scene.instances[i].qpos_adr.unwrap();
        self.data.qpos_mut()[a..a + 7]
            .copy_from_slice(&[pos[0], pos[1], pos[2], 1.0, 0.0, 0.0, 0.0]);
    }

    fn joint(&mut self, inst: &str, k: usize, q: f64) {
        let i = self.scene.instance(inst).unwrap();
        let adr = self.scene.instances[i].joints[k].1;
        self.data.qpos_mut()[adr] = q;
    }

    /// Lets objects drop into contact (the arm is held by its joint limits/gravity only briefly).
    fn settle(&mut self, steps: usize) {
        self.data.qvel_mut().fill(0.0);
        for _ in 0..steps {
            let bias: Vec<f64> = self.data.qfrc_bias()[..7].to_vec();
            self.data.ctrl_mut()[..7].copy_from_slice(&bias);
            self.data.step().unwrap();
        }
        self.data.forward().unwrap();
    }

    fn eval(&self, pred: &str, args: &[&str]) -> bool {
        let args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
        Predicates::new(&self.scene, &self.data)
            .eval(pred, &args)
            .unwrap()
    }
}

#[test]
fn bowl_on_plate_yes_and_no() {
    let mut f = Fixture::new();
    f.put("plate_1", [0.1, 0.1, 0.905]);
    f.put("akita_black_bowl_1", [0.1, 0.1, 0.915]);
    f.settle(300);
    assert!(f.eval("on", &["akita_black_bowl_1", "plate_1"]));
    assert!(
        !f.eval("on", &["plate_1", "akita_black_bowl_1"]),
        "plate is below the bowl"
    );
    // Beside the plate: no contact, too far.
    f.put("akita_black_bowl_1", [0.1, -0.1, 0.905]);
    f.settle(200);
    assert!(!f.eval("on", &["akita_black_bowl_1", "plate_1"]));
    // Touching the plate's rim but 5 cm off-centre: contact yes, xy distance too large.
    f.put("akita_black_bowl_1", [0.1, 0.05, 0.925]);
    f.settle(300);
    assert!(!f.eval("on", &["akita_black_bowl_1", "plate_1"]));
}

#[test]
fn cheese_in_basket_yes_and_no() {
    let mut f = Fixture::new();
    f.put("basket_1", [0.05, 0.0, 0.905]);
    f.put("cream_cheese_1", [0.05, 0.0, 0.93]);
    f.settle(300);
    assert!(f.eval("in", &["cream_cheese_1", "basket_1_contain_region"]));
    f.put("cream_cheese_1", [0.05, 0.2, 0.91]);
    f.settle(200);
    assert!(!f.eval("in", &["cream_cheese_1", "basket_1_contain_region"]));
    // The basket on the centre region (a TargetZone: no contact test).
    assert!(f.eval("on", &["basket_1", "kitchen_table_the_center"]));
    f.put("basket_1", [-0.3, -0.1, 0.905]);
    f.settle(200);
    assert!(!f.eval("on", &["basket_1", "kitchen_table_the_center"]));
}

#[test]
fn drawer_open_and_closed() {
    let mut f = Fixture::new();
    f.joint("wooden_cabinet_1", 0, 0.003);
    f.settle(1);
    assert!(f.eval("close", &["wooden_cabinet_1_top_region"]));
    assert!(!f.eval("open", &["wooden_cabinet_1_top_region"]));
    f.joint("wooden_cabinet_1", 0, -0.15);
    f.settle(1);
    assert!(f.eval("open", &["wooden_cabinet_1_top_region"]));
    assert!(
        f.eval("open", &["wooden_cabinet_1"]),
        "any drawer open opens the cabinet"
    );
    assert!(!f.eval("close", &["wooden_cabinet_1"]));
    // The open drawer moved toward world +y (yaw π): its region site followed.
    let s = f.scene.regions["wooden_cabinet_1_top_region"].site.unwrap();
    assert!(
        f.data.site_pos(s)[1] > -0.40 + 0.1,
        "{:?}",
        f.data.site_pos(s)
    );
    // Something inside the open drawer is In its region.
    let p = f.data.site_pos(s);
    f.put("cream_cheese_1", [p[0], p[1], p[2] - 0.015]);
    f.settle(100);
    assert!(f.eval("in", &["cream_cheese_1", "wooden_cabinet_1_top_region"]));
}

#[test]
fn stove_on_and_off() {
    let mut f = Fixture::new();
    f.joint("flat_stove_1", 0, -0.003);
    f.settle(1);
    assert!(f.eval("turnoff", &["flat_stove_1"]) && !f.eval("turnon", &["flat_stove_1"]));
    f.joint("flat_stove_1", 0, 0.6);
    f.settle(1);
    assert!(f.eval("turnon", &["flat_stove_1"]) && !f.eval("turnoff", &["flat_stove_1"]));
    // A bowl on the burner is On the cook region (with contact to the stove).
    f.put("akita_black_bowl_1", [-0.15, 0.35, 0.915]);
    f.settle(300);
    assert!(f.eval("on", &["akita_black_bowl_1", "flat_stove_1_cook_region"]));
    assert!(!f.eval("up", &["akita_black_bowl_1"]));
}

#[test]
fn bad_predicates_are_errors() {
    let f = Fixture::new();
    let p = Predicates::new(&f.scene, &f.data);
    assert!(
        p.eval("levitate", &["plate_1".into()])
            .unwrap_err()
            .to_string()
            .contains("unknown predicate")
    );
    assert!(
        p.eval("on", &["plate_1".into()])
            .unwrap_err()
            .to_string()
            .contains("2 argument")
    );
    assert!(
        p.eval("on", &["plate_9".into(), "plate_1".into()])
            .unwrap_err()
            .to_string()
            .contains("plate_9")
    );
}

/// The wine rack with one bottle: the rack (yaw π, as in LIBERO-Goal) at a fixed pose.
fn rack_fixture() -> (Fixture, [f64; 3]) {
    let region = |name: &str, target: &str| RegionSpec {
        name: name.into(),
        target: target.into(),
        ranges: vec![],
        yaw: [0.0, 0.0],
        rgba: [0.0, 0.0, 1.0, 0.0],
    };
    let inst = |n: &str, c: &str| InstanceSpec {
        name: n.into(),
        category: c.into(),
    };
    let spec = SceneSpec {
        problem_class: "libero_kitchen_tabletop_manipulation".into(),
        regions: vec![region("top_region", "wine_rack_1")],
        fixtures: vec![
            inst("kitchen_table", "kitchen_table"),
            inst("wine_rack_1", "wine_rack"),
        ],
        objects: vec![inst("wine_bottle_1", "wine_bottle")],
        init: vec![],
    };
    let scene = Scene::build(spec).unwrap();
    let mut data = Data::new(scene.model.clone()).unwrap();
    data.qpos_mut()[..7].copy_from_slice(&sim::robot::INIT_QPOS);
    let mut f = Fixture { scene, data };
    let rack = [-0.26, -0.26, 0.92];
    f.fixture("wine_rack_1", rack, std::f64::consts::PI);
    f.put("wine_bottle_1", [0.3, 0.3, 0.905]);
    (f, rack)
}

fn qmul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

impl Fixture {
    /// Puts the wine bottle with its bottom centre at `p` (world) and orientation `q` (wxyz).
    fn put_posed(&mut self, name: &str, p: [f64; 3], q: [f64; 4]) {
        let i = self.scene.instance(name).unwrap();
        let a = self.scene.instances[i].qpos_adr.unwrap();
        self.data.qpos_mut()[a..a + 7].copy_from_slice(&[p[0], p[1], p[2], q[0], q[1], q[2], q[3]]);
    }

    fn body(&self, name: &str) -> ([f64; 3], [f64; 4]) {
        let b = self.scene.instances[self.scene.instance(name).unwrap()].root_body;
        (self.data.body_pos(b), self.data.body_quat(b))
    }
}

/// A bottle let go on the rack's top shelf, along its incline (neck up) or across it, slides or rolls
/// down against the stopper and stays there, inside `top_region`; on the lower shelf or standing on
/// the table it is not on the rack's top.
#[test]
fn a_bottle_rests_against_the_top_stopper_of_the_rack() {
    let shelf = sim::assets::wine_rack_top_shelf();
    assert!((shelf.stopper + 0.0734).abs() < 5e-4, "{shelf:?}");
    let r = 0.0215;
    // Rack frame (yaw π) to world.
    let world = |rack: [f64; 3], x: f64, y: f64, z: f64| [rack[0] - x, rack[1] - y, rack[2] + z];
    let on_shelf = |s: f64, h: f64| {
        [
            shelf.surface[0] + s * shelf.incline[0] + h * shelf.normal[0],
            shelf.surface[1] + s * shelf.incline[1] + h * shelf.normal[1],
        ]
    };
    let yaw = sim::assets::yaw_quat(std::f64::consts::PI);
    let about_x = |a: f64| [(a / 2.0).cos(), (a / 2.0).sin(), 0.0, 0.0];
    let angle = shelf.incline[1].atan2(shelf.incline[0]);

    // Along the incline, bottom 2 cm up the shelf from the stopper and 5 mm above it.
    let (mut f, rack) = rack_fixture();
    let [y, z] = on_shelf(shelf.stopper + 0.02, r + 0.005);
    let q = qmul(yaw, about_x(angle - std::f64::consts::FRAC_PI_2));
    f.put_posed("wine_bottle_1", world(rack, 0.06, y, z), q);
    f.settle(1500);
    assert!(f.eval("on", &["wine_bottle_1", "wine_rack_1_top_region"]));
    let (p, q) = f.body("wine_bottle_1");
    let [y, z] = on_shelf(shelf.stopper, r);
    let rest = world(rack, 0.06, y, z);
    let d = ((p[0] - rest[0]).powi(2) + (p[1] - rest[1]).powi(2) + (p[2] - rest[2]).powi(2)).sqrt();
    assert!(
        d < 0.004,
        "bottom centre {p:?}, expected against the stopper at {rest:?}"
    );
    // Still along the incline: the bottle's axis rises at the shelf's angle.
    let axis_z = 1.0 - 2.0 * (q[1] * q[1] + q[2] * q[2]);
    assert!((axis_z - angle.sin()).abs() < 0.03, "axis z {axis_z}");

    // Across the shelf (along x), just up from the stopper: it rolls against it. (From a few
    // centimetres up it gathers enough speed to jump the 1.4 cm stopper: the expert lays bottles
    // along the incline.)
    let (mut f, rack) = rack_fixture();
    let [y, z] = on_shelf(shelf.stopper + 0.005 + r, r + 0.003);
    let q = qmul(yaw, about_x(0.0));
    let across = qmul(
        q,
        [
            std::f64::consts::FRAC_1_SQRT_2,
            0.0,
            std::f64::consts::FRAC_1_SQRT_2,
            0.0,
        ],
    );
    f.put_posed("wine_bottle_1", world(rack, -0.05, y, z), across);
    f.settle(1500);
    assert!(f.eval("on", &["wine_bottle_1", "wine_rack_1_top_region"]));
    let (p, _) = f.body("wine_bottle_1");
    let [y, _] = on_shelf(shelf.stopper + r, r);
    assert!(
        (p[1] - (rack[1] - y)).abs() < 0.005,
        "axis at y {} not against the stopper",
        p[1]
    );

    // On the lower shelf, or standing on the table beside the rack: not on the top region.
    let (mut f, rack) = rack_fixture();
    let low = [
        -0.04273 + 0.0045 * shelf.normal[0],
        0.12727 + 0.0045 * shelf.normal[1],
    ];
    let (y, z) = (
        low[0] + (r + 0.005) * shelf.normal[0],
        low[1] + (r + 0.005) * shelf.normal[1],
    );
    f.put_posed(
        "wine_bottle_1",
        world(rack, 0.06, y, z),
        qmul(yaw, about_x(angle - std::f64::consts::FRAC_PI_2)),
    );
    f.settle(1500);
    assert!(!f.eval("on", &["wine_bottle_1", "wine_rack_1_top_region"]));
    f.put("wine_bottle_1", [-0.26, -0.05, 0.905]);
    f.settle(300);
    assert!(!f.eval("on", &["wine_bottle_1", "wine_rack_1_top_region"]));
}
