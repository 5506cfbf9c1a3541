//! The MJCF of the built-in assets: each category's bodies, geoms, sites and joints from primitives,
//! under an instance's names ([`instance_xml`]), and the geometry helpers they share.

use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt::Write;

use super::bits;
use super::def::{AssetDef, AssetKind};
use crate::task::Category;

/// Half sizes of a cabinet drawer's region site (and of the drawer's inside).
pub(super) const DRAWER_REGION_HALF: [f64; 3] = [0.02993, 0.07561, 0.10224];

fn qmul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

fn qz(a: f64) -> [f64; 4] {
    [(a / 2.0).cos(), 0.0, 0.0, (a / 2.0).sin()]
}

fn qy(a: f64) -> [f64; 4] {
    [(a / 2.0).cos(), 0.0, (a / 2.0).sin(), 0.0]
}

fn qx(a: f64) -> [f64; 4] {
    [(a / 2.0).cos(), (a / 2.0).sin(), 0.0, 0.0]
}

fn f(v: f64) -> String {
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.to_string() }
}

fn v3(v: [f64; 3]) -> String {
    format!("{} {} {}", f(v[0]), f(v[1]), f(v[2]))
}

fn v4(v: [f64; 4]) -> String {
    format!("{} {} {} {}", f(v[0]), f(v[1]), f(v[2]), f(v[3]))
}

/// Writes geoms into an MJCF body. All geoms of an asset collide with the robot and each other.
struct Geoms<'a> {
    out: &'a mut String,
    prefix: &'a str,
    n: usize,
    rgba: [f64; 4],
    friction: &'static str,
    /// Extra attributes (solref/solimp) shared by the asset's geoms.
    contact: &'static str,
    /// `contype` / `conaffinity`.
    bits: (u32, u32),
}

impl Geoms<'_> {
    fn geom(&mut self, kind: &str, pos: [f64; 3], quat: [f64; 4], size: &str, mass: f64) {
        let _ = writeln!(
            self.out,
            r#"<geom name="{p}_g{n}" type="{kind}" pos="{}" quat="{}" size="{size}" mass="{}" rgba="{}" friction="{}" contype="{ct}" conaffinity="{ca}" group="1" {}/>"#,
            v3(pos),
            v4(quat),
            f(mass),
            v4(self.rgba),
            self.friction,
            self.contact,
            p = self.prefix,
            n = self.n,
            ct = self.bits.0,
            ca = self.bits.1,
        );
        self.n += 1;
    }

    fn bx(&mut self, pos: [f64; 3], half: [f64; 3], mass: f64) {
        self.geom("box", pos, [1.0, 0.0, 0.0, 0.0], &v3(half), mass);
    }

    fn bx_rot(&mut self, pos: [f64; 3], quat: [f64; 4], half: [f64; 3], mass: f64) {
        self.geom("box", pos, quat, &v3(half), mass);
    }

    fn cyl(&mut self, pos: [f64; 3], radius: f64, half_height: f64, mass: f64) {
        self.geom(
            "cylinder",
            pos,
            [1.0, 0.0, 0.0, 0.0],
            &format!("{} {}", f(radius), f(half_height)),
            mass,
        );
    }

    /// A ring of `n` boxes forming a (possibly flared) wall from radius `r0` at `z0` to `r1` at `z1`.
    #[allow(clippy::too_many_arguments)]
    fn ring(&mut self, n: usize, r0: f64, r1: f64, z0: f64, z1: f64, thickness: f64, mass: f64) {
        let tilt = (r1 - r0).atan2(z1 - z0);
        let slant = ((r1 - r0).powi(2) + (z1 - z0).powi(2)).sqrt();
        let rm = 0.5 * (r0 + r1);
        let zm = 0.5 * (z0 + z1);
        // Tangential half-width: a little overlap so the wall has no gaps.
        let half_w = (PI / n as f64).tan() * (rm + thickness / 2.0) * 1.08;
        for i in 0..n {
            let th = 2.0 * PI * i as f64 / n as f64;
            let q = qmul(qz(th), qy(tilt));
            self.bx_rot(
                [rm * th.cos(), rm * th.sin(), zm],
                q,
                [thickness / 2.0, half_w, slant / 2.0],
                mass / n as f64,
            );
        }
    }
}

fn site(out: &mut String, prefix: &str, name: &str, pos: [f64; 3], quat: [f64; 4], half: [f64; 3]) {
    let _ = writeln!(
        out,
        r#"<site name="{prefix}_{name}" type="box" pos="{}" quat="{}" size="{}" rgba="0 0 1 0" group="3"/>"#,
        v3(pos),
        v4(quat),
        v3(half)
    );
}

/// LIBERO's collision-geom contact parameters (solref 0.001 is clamped to 2·dt by MuJoCo's refsafe).
const OBJ_CONTACT: &str = r#"solref="0.01 1""#;
const OBJ_FRICTION: &str = "0.95 0.3 0.1";

/// MJCF body tree for one instance of `def`, named `<instance>_main`, at `pos`/`quat` (world frame).
pub fn instance_xml(def: &AssetDef, instance: &str, pos: [f64; 3], quat: [f64; 4]) -> String {
    let mut out = String::new();
    let p = instance;
    let head = match def.kind {
        AssetKind::Movable => format!(
            r#"<body name="{p}_main" pos="{}" quat="{}">
<freejoint name="{p}_joint0"/>
"#,
            v3(pos),
            v4(quat)
        ),
        AssetKind::Fixture => format!(
            r#"<body name="{p}_main" pos="{}" quat="{}" mocap="true">
"#,
            v3(pos),
            v4(quat)
        ),
    };
    out.push_str(&head);
    match def.builtin {
        Some(Category::AkitaBlackBowl) => bowl(&mut out, p),
        Some(Category::Plate) => plate(&mut out, p),
        Some(Category::Basket) => basket(&mut out, p),
        Some(Category::CreamCheese) => cream_cheese(&mut out, p),
        Some(Category::WineBottle) => wine_bottle(&mut out, p),
        Some(Category::WineRack) => wine_rack(&mut out, p),
        Some(Category::FlatStove) => flat_stove(&mut out, p),
        Some(Category::WoodenCabinet) => wooden_cabinet(&mut out, p),
        Some(Category::WhiteCabinet) | None => {
            unreachable!("asset {} listed without geometry", def.category)
        }
    }
    out.push_str("</body>\n");
    out
}

fn geoms<'a>(out: &'a mut String, prefix: &'a str, rgba: [f64; 4]) -> Geoms<'a> {
    Geoms {
        out,
        prefix,
        n: 0,
        rgba,
        friction: OBJ_FRICTION,
        contact: OBJ_CONTACT,
        bits: (bits::OBJECT_TYPE, bits::OBJECT_AFFINITY),
    }
}

fn frame_bits(g: &mut Geoms) {
    g.bits = (bits::FRAME_TYPE, bits::FIXTURE_AFFINITY);
}

fn part_bits(g: &mut Geoms) {
    g.bits = (bits::PART_TYPE, bits::FIXTURE_AFFINITY);
}

/// Akita black bowl: Ø 0.107 m, 0.05 m tall, origin at the bottom centre, thin flared wall whose top edge
/// is a rim fingers can pinch. The foot is a box: box–box contacts are MuJoCo's cheapest
/// stable ones, and only the foot touches what the bowl stands on.
fn bowl(out: &mut String, p: &str) {
    let mut g = geoms(out, p, [0.06, 0.06, 0.065, 1.0]);
    g.bx([0.0, 0.0, 0.005], [0.027, 0.027, 0.003], 0.0016);
    g.ring(12, 0.036, 0.0535, 0.006, 0.052, 0.005, 0.004);
}

/// Plate: Ø 0.138 m, 0.019 m tall (z −0.0025…0.0164): a flat square centre and a low rim that does
/// not reach the table.
fn plate(out: &mut String, p: &str) {
    let mut g = geoms(out, p, [0.92, 0.92, 0.88, 1.0]);
    g.bx([0.0, 0.0, 0.0005], [0.05, 0.05, 0.003], 0.007);
    g.ring(12, 0.056, 0.069, 0.001, 0.0164, 0.004, 0.0045);
}

/// Basket: 0.17 × 0.157 × 0.141 m, open top, thin walls whose upper edge is a graspable rim.
fn basket(out: &mut String, p: &str) {
    let (hx, hy, top, t) = (0.085, 0.0785, 0.1457, 0.006);
    {
        let mut g = geoms(out, p, [0.62, 0.45, 0.25, 1.0]);
        g.bx([0.0, 0.0, 0.0042 + 0.004], [hx, hy, 0.004], 0.04);
        let zc = (0.0042 + top) / 2.0;
        let hz = (top - 0.0042) / 2.0;
        g.bx([hx - t / 2.0, 0.0, zc], [t / 2.0, hy, hz], 0.024);
        g.bx([-hx + t / 2.0, 0.0, zc], [t / 2.0, hy, hz], 0.024);
        g.bx([0.0, hy - t / 2.0, zc], [hx - t, t / 2.0, hz], 0.024);
        g.bx([0.0, -hy + t / 2.0, zc], [hx - t, t / 2.0, hz], 0.024);
    }
    site(
        out,
        p,
        "contain_region",
        [0.0, 0.0, 0.07185],
        [0.0, 0.0, 0.0, 1.0],
        [0.06108, 0.06108, 0.06949],
    );
}

/// Cream cheese box: 0.081 × 0.043 × 0.018 m, centred on its origin.
fn cream_cheese(out: &mut String, p: &str) {
    let mut g = geoms(out, p, [0.82, 0.84, 0.9, 1.0]);
    g.bx([0.0, 0.0, 0.0], [0.0405, 0.0215, 0.009], 0.0062);
    let mut lid = geoms(g.out, p, [0.25, 0.35, 0.75, 1.0]);
    lid.n = 1;
    lid.geom(
        "box",
        [0.0, 0.0, 0.0091],
        [1.0, 0.0, 0.0, 0.0],
        "0.03 0.015 0.0002",
        0.0,
    );
}

/// Wine bottle: Ø 0.043 m, 0.157 m tall, upright, origin at the bottom.
fn wine_bottle(out: &mut String, p: &str) {
    let mut g = geoms(out, p, [0.12, 0.28, 0.14, 1.0]);
    g.cyl([0.0, 0.0, 0.053], 0.0215, 0.052, 0.011);
    g.cyl([0.0, 0.0, 0.1125], 0.015, 0.0075, 0.002);
    g.cyl([0.0, 0.0, 0.139], 0.009, 0.019, 0.0015);
    let mut cap = geoms(g.out, p, [0.55, 0.1, 0.12, 1.0]);
    cap.n = 3;
    cap.cyl([0.0, 0.0, 0.1545], 0.0095, 0.0035, 0.0005);
}

/// Angle of the wine rack's shelves above the horizontal, rising towards the rack's +y (degrees).
const RACK_SHELF_DEG: f64 = 31.28;
/// Centre (y, z) of the rack's top shelf board in the rack's frame; half size (x, along, thickness).
const RACK_TOP_SHELF: [f64; 2] = [-0.0061, 0.25118];
const RACK_SHELF_HALF: [f64; 3] = [0.13438, 0.07894, 0.0045];
/// Centre (y, z) of the stopper along the top shelf's lower edge, its angle (degrees) and half size
/// (x, thickness, height).
const RACK_TOP_STOPPER: [f64; 2] = [-0.07477, 0.22072];
const RACK_STOPPER_DEG: f64 = 29.3;
const RACK_STOPPER_HALF: [f64; 3] = [0.13222, 0.00108, 0.00867];

/// The wine rack's top shelf in the rack's frame, in the (y, z) plane: what a bottle laid in the rack
/// rests on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RackShelf {
    /// A point of the upper surface, above the board's centre.
    pub surface: [f64; 2],
    /// Unit vector up the incline.
    pub incline: [f64; 2],
    /// Unit normal of the upper surface.
    pub normal: [f64; 2],
    /// Where the stopper's upper face crosses the incline, from `surface` along `incline` (m).
    pub stopper: f64,
    /// Half length of the shelf along x (m).
    pub half_x: f64,
}

/// The top shelf of the builtin wine rack (LIBERO's layout, so it also describes the pack's rack).
pub fn wine_rack_top_shelf() -> RackShelf {
    let a = RACK_SHELF_DEG.to_radians();
    let incline = [a.cos(), a.sin()];
    let normal = [-a.sin(), a.cos()];
    let surface = [
        RACK_TOP_SHELF[0] + RACK_SHELF_HALF[2] * normal[0],
        RACK_TOP_SHELF[1] + RACK_SHELF_HALF[2] * normal[1],
    ];
    let b = RACK_STOPPER_DEG.to_radians();
    let face = [
        RACK_TOP_STOPPER[0] + RACK_STOPPER_HALF[1] * b.cos(),
        RACK_TOP_STOPPER[1] + RACK_STOPPER_HALF[1] * b.sin(),
    ];
    let stopper = (face[0] - surface[0]) * incline[0] + (face[1] - surface[1]) * incline[1];
    RackShelf {
        surface,
        incline,
        normal,
        stopper,
        half_x: RACK_SHELF_HALF[0],
    }
}

/// Wine rack: 0.269 × 0.254 × 0.33 m, laid out as LIBERO's collision model: a footed base, a central
/// post leaning 16° towards +y, and two shelves inclined 31.3° (rising towards +y) with a 1.4 cm
/// stopper along each lower edge. Bottles lie on a shelf against its stopper; the `top_region` site
/// sits at the top stopper and its box reaches 10 cm up the shelf (see `under`).
fn wine_rack(out: &mut String, p: &str) {
    let q_site = [0.8549119, -0.5187733, 0.0, 0.0];
    let site_pos = [0.0, -0.08003, 0.21745];
    // (centre y, centre z, half [x, y, z], angle of the box's y axis above +y in degrees, mass)
    let parts: [(f64, f64, [f64; 3], f64, f64); 9] = [
        // Base plate, two splayed feet and a cross bar.
        (0.0, 0.00657, [0.06646, 0.09302, 0.0045], 0.0, 0.04),
        (0.06935, 0.01006, [0.08995, 0.06004, 0.00447], -7.48, 0.02),
        (-0.0643, 0.01263, [0.08995, 0.06004, 0.00447], 8.04, 0.02),
        (0.0, 0.0205, [0.09045, 0.0141, 0.0045], 0.0, 0.01),
        // Post.
        (0.00886, 0.17026, [0.00762, 0.00905, 0.16165], -15.84, 0.02),
        // Shelves.
        (
            RACK_TOP_SHELF[0],
            RACK_TOP_SHELF[1],
            RACK_SHELF_HALF,
            RACK_SHELF_DEG,
            0.02,
        ),
        (-0.04273, 0.12727, RACK_SHELF_HALF, RACK_SHELF_DEG, 0.02),
        // Stoppers: thin plates standing across the shelves' lower edges.
        (
            RACK_TOP_STOPPER[0],
            RACK_TOP_STOPPER[1],
            RACK_STOPPER_HALF,
            RACK_STOPPER_DEG,
            0.005,
        ),
        (
            -0.10912,
            0.09735,
            RACK_STOPPER_HALF,
            RACK_STOPPER_DEG,
            0.005,
        ),
    ];
    let mut g = geoms(out, p, [0.45, 0.30, 0.18, 1.0]);
    frame_bits(&mut g);
    for (y, z, half, deg, mass) in parts {
        let a = deg.to_radians() / 2.0;
        g.bx_rot([0.0, y, z], [a.cos(), a.sin(), 0.0, 0.0], half, mass);
    }
    site(
        out,
        p,
        "top_region",
        site_pos,
        q_site,
        [0.10087, 0.022, 0.00251],
    );
}

/// Flat stove: 0.297 × 0.19 × 0.07 m; knob (hinge `button`, axis z) at the origin, burner at +0.15 x.
/// The knob is a light part (100 g, damping 0.02) rather than LIBERO's placeholder inertial (3 kg,
/// 1 kg·m², damping 1), which no fingertip force could turn by the 0.5 rad `turn_on` needs.
fn flat_stove(out: &mut String, p: &str) {
    {
        let mut g = geoms(out, p, [0.2, 0.2, 0.22, 1.0]);
        frame_bits(&mut g);
        g.friction = "1 0.005 0.0001";
        g.contact = r#"solref="0.02 1""#;
        // Cook top slab and burner plate (the cook region sits on its surface).
        // The burner surface is 6 mm above the cook-region site, so a resting object's origin sits inside
        // `under()`'s window (−2.5 mm … +10 cm) despite contact softness.
        g.bx([0.1475, 0.0, -0.005], [0.0975, 0.095, 0.009], 1.0);
        g.cyl([0.15, 0.0, 0.005], 0.07, 0.001, 0.3);
        // Control box under the knob.
        g.bx([-0.001, 0.0, 0.01], [0.051, 0.06, 0.028], 0.2);
    }
    site(
        out,
        p,
        "cook_region",
        [0.15, 0.0, 0.0],
        [1.0, 0.0, 0.0, 0.0],
        [0.075, 0.075, 0.0025],
    );
    let _ = writeln!(
        out,
        r#"<site name="{p}_burner" type="cylinder" pos="0.15 0 0.022" size="0.0625 0.0005" rgba="1 0.15 0.05 0" group="1"/>"#
    );
    let _ = writeln!(
        out,
        r#"<body name="{p}_knob" pos="0 0 0.038">
<inertial pos="0 0 0.01" mass="0.1" diaginertia="0.0002 0.0002 0.0002"/>
<joint name="{p}_button" type="hinge" axis="0 0 1" range="-0.005 2.1" limited="true" damping="0.02" armature="0.0005"/>"#
    );
    {
        let mut g = geoms(out, p, [0.85, 0.85, 0.87, 1.0]);
        part_bits(&mut g);
        g.n = 10;
        g.friction = "1 0.005 0.0001";
        g.contact = r#"solref="0.02 1""#;
        g.cyl([0.0, 0.0, 0.008], 0.022, 0.008, 0.0);
        // Pointer bar: what the gripper pinches to turn the knob.
        g.bx([0.0, 0.0, 0.024], [0.004, 0.02, 0.008], 0.0);
    }
    out.push_str("</body>\n");
}

/// Wooden cabinet: 0.255 × 0.221 × 0.218 m carcass with three drawers sliding along local −y (range
/// [−0.16, 0.01]), each with a handle; `top_side` on the carcass top, one `*_region` inside each drawer.
fn wooden_cabinet(out: &mut String, p: &str) {
    let wood = [0.55, 0.36, 0.2, 1.0];
    let (hx, y_back, y_front, z0, z1, t) = (0.1275, 0.126, -0.095, 0.005, 0.223, 0.008);
    let yc = 0.5 * (y_back + y_front);
    let hy = 0.5 * (y_back - y_front);
    {
        let mut g = geoms(out, p, wood);
        frame_bits(&mut g);
        g.bx(
            [hx - t / 2.0, yc, (z0 + z1) / 2.0],
            [t / 2.0, hy, (z1 - z0) / 2.0],
            0.03,
        );
        g.bx(
            [-hx + t / 2.0, yc, (z0 + z1) / 2.0],
            [t / 2.0, hy, (z1 - z0) / 2.0],
            0.03,
        );
        g.bx(
            [0.0, y_back - t / 2.0, (z0 + z1) / 2.0],
            [hx - t, t / 2.0, (z1 - z0) / 2.0],
            0.03,
        );
        g.bx([0.0, yc, z1 - t / 2.0], [hx, hy, t / 2.0], 0.03);
        g.bx([0.0, yc, z0 + t / 2.0], [hx - t, hy, t / 2.0], 0.03);
        // Shelves between the drawers.
        for &z in &[0.0815, 0.152] {
            g.bx([0.0, yc, z], [hx - t, hy, 0.003], 0.01);
        }
    }
    site(
        out,
        p,
        "top_side",
        [0.00354, 0.01567, 0.22152],
        [1.0, 0.0, 0.0, 0.0],
        [0.12534, 0.09438, 0.00147],
    );
    let region_q = [
        std::f64::consts::FRAC_1_SQRT_2,
        0.0,
        std::f64::consts::FRAC_1_SQRT_2,
        0.0,
    ];
    for (level, region, zc, n0) in [
        ("top_level", "top_region", 0.18563, 20),
        ("middle_level", "middle_region", 0.11690, 30),
        ("bottom_level", "bottom_region", 0.04701, 40),
    ] {
        let _ = writeln!(
            out,
            r#"<body name="{p}_{level}_drawer" pos="0 0 0">
<inertial pos="0 0.01 {}" mass="3" diaginertia="1 1 1"/>
<joint name="{p}_{level}" type="slide" axis="0 1 0" range="-0.16 0.01" limited="true" damping="50"/>"#,
            f(zc)
        );
        {
            let mut g = geoms(out, p, [0.6, 0.4, 0.22, 1.0]);
            part_bits(&mut g);
            g.n = n0;
            let (dx, dy0, dy1) = (0.106, -0.086, 0.112);
            let (bot, top) = (zc - 0.031, zc + 0.027);
            let dyc = 0.5 * (dy0 + dy1);
            let dhy = 0.5 * (dy1 - dy0);
            let wall_h = 0.5 * (top - bot);
            g.bx([0.0, dyc, bot + 0.002], [dx, dhy, 0.002], 0.0);
            g.bx([dx - 0.002, dyc, bot + wall_h], [0.002, dhy, wall_h], 0.0);
            g.bx([-dx + 0.002, dyc, bot + wall_h], [0.002, dhy, wall_h], 0.0);
            g.bx([0.0, dy1 - 0.002, bot + wall_h], [dx, 0.002, wall_h], 0.0);
            // Front panel (closes the carcass) and the handle.
            g.bx([0.0, dy0 - 0.006, zc - 0.002], [0.118, 0.006, 0.032], 0.0);
            let mut h = geoms(g.out, p, [0.75, 0.72, 0.65, 1.0]);
            part_bits(&mut h);
            h.n = n0 + 5;
            // A 5 cm bar standing 2.5 cm proud of the front on two posts: room for a fingertip behind it
            // and for the fingers around its ends.
            h.bx([0.0, dy0 - 0.042, zc], [0.025, 0.005, 0.006], 0.0);
            h.bx([0.017, dy0 - 0.0245, zc], [0.004, 0.0125, 0.005], 0.0);
            h.bx([-0.017, dy0 - 0.0245, zc], [0.004, 0.0125, 0.005], 0.0);
        }
        site(
            out,
            p,
            region,
            [0.00328, 0.01128, zc],
            region_q,
            DRAWER_REGION_HALF,
        );
        out.push_str("</body>\n");
    }
}

/// Quaternion of a yaw `a` about z (wxyz), as LIBERO's fixture sampler writes it.
pub fn yaw_quat(a: f64) -> [f64; 4] {
    qz(a)
}

/// `x`-axis rotation quaternion (wxyz).
pub fn x_quat(a: f64) -> [f64; 4] {
    qx(a)
}

/// Right angle, for callers composing placement quaternions.
pub const RIGHT_ANGLE: f64 = FRAC_PI_2;
