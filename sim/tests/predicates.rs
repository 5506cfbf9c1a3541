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
