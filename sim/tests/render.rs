//! Rendering: RGB, depth against mj_ray, segmentation against known objects, bad input.

use std::sync::Arc;

use sim::mujoco::{Data, Model, ObjType};
use sim::render::{Channels, RenderError, RenderQuality, Renderer, geoms_to_bodies};

/// A floor, a red box left of centre and a blue sphere right of centre, seen from straight above.
const SCENE: &str = r#"
<mujoco>
  <compiler autolimits="true"/>
  <visual><headlight ambient="0.6 0.6 0.6" diffuse="0.3 0.3 0.3"/></visual>
  <worldbody>
    <light pos="0 0 3" dir="0 0 -1"/>
    <geom name="floor" type="plane" size="2 2 0.1" rgba="0.5 0.5 0.5 1" group="1"/>
    <body name="red_box" pos="0 0.3 0.1">
      <geom name="red_box_g" type="box" size="0.1 0.1 0.1" rgba="1 0 0 1" group="1"/>
    </body>
    <body name="blue_ball" pos="0 -0.3 0.15">
      <geom name="blue_ball_g" type="sphere" size="0.15" rgba="0 0 1 1" group="1"/>
    </body>
    <camera name="top" pos="0 0 2" quat="1 0 0 0" fovy="60"/>
  </worldbody>
</mujoco>"#;

fn setup() -> (Arc<Model>, Data, Renderer) {
    let model = Arc::new(Model::from_xml_str(SCENE).unwrap());
    let mut data = Data::new(model.clone()).unwrap();
    data.forward().unwrap();
    let r = Renderer::new(&model, 128, 128, RenderQuality::default()).unwrap();
    (model, data, r)
}

/// World ray direction through pixel (row, col) of the top camera (looking down −z, image up = +y).
fn pixel_ray(row: usize, col: usize, size: usize, fovy_deg: f64) -> [f64; 3] {
    let f = (size as f64 / 2.0) / (fovy_deg.to_radians() / 2.0).tan();
    let u = (col as f64 + 0.5) - size as f64 / 2.0;
    let v = (row as f64 + 0.5) - size as f64 / 2.0;
    // camera x = world x (image right), camera y = world y (image up), camera looks along −z.
    [u / f, -v / f, -1.0]
}

#[test]
fn renders_rgb_with_objects_where_expected() {
    let (_m, mut data, mut r) = setup();
    assert!(!r.gl_info().renderer.is_empty());
    let f = r
        .render_named(&mut data, "top", 128, Channels::RGB)
        .unwrap();
    let rgb = f.rgb.unwrap();
    assert_eq!(rgb.len(), 128 * 128 * 3);
    let px = |row: usize, col: usize| {
        let i = 3 * (row * 128 + col);
        [rgb[i], rgb[i + 1], rgb[i + 2]]
    };
    // The red box is at world +y = image top half; the blue ball at −y = bottom half.
    let top = px(64 - 18, 64);
    let bottom = px(64 + 18, 64);
    assert!(
        top[0] > 150 && top[1] < 110 && top[2] < 110,
        "top pixel {top:?}"
    );
    assert!(
        bottom[2] > 150 && bottom[0] < 110 && bottom[1] < 110,
        "bottom pixel {bottom:?}"
    );
}

#[test]
fn depth_agrees_with_mj_ray_to_1cm() {
    let (_m, mut data, mut r) = setup();
    let f = r
        .render_named(&mut data, "top", 128, Channels::ALL)
        .unwrap();
    let depth = f.depth.unwrap();
    let mut checked = 0;
    for &(row, col) in &[(64, 64), (46, 64), (82, 64), (10, 10), (100, 30), (64, 120)] {
        let dir = pixel_ray(row, col, 128, 60.0);
        let (dist, _) = data
            .ray([0.0, 0.0, 2.0], dir, -1)
            .expect("ray hits something");
        // mj_ray returns distance in units of |dir|; dir has unit z, so depth along the axis = dist.
        let d = depth[row * 128 + col] as f64;
        assert!(
            (d - dist).abs() < 0.01,
            "pixel ({row},{col}): render {d} vs ray {dist}"
        );
        checked += 1;
    }
    assert_eq!(checked, 6);
}

#[test]
fn segmentation_names_the_right_objects() {
    let (model, mut data, mut r) = setup();
    let f = r
        .render_named(
            &mut data,
            "top",
            96,
            Channels {
                rgb: false,
                depth: false,
                segmentation: true,
            },
        )
        .unwrap();
    let seg = f.segmentation.unwrap();
    let bodies = geoms_to_bodies(&model, &seg);
    let name = |row: usize, col: usize| {
        let b = bodies[row * 96 + col];
        assert!(b >= 0, "pixel ({row},{col}) has no body");
        model
            .name(ObjType::Body, b as usize)
            .unwrap_or("world")
            .to_string()
    };
    assert_eq!(name(48 - 14, 48), "red_box");
    assert_eq!(name(48 + 14, 48), "blue_ball");
    assert_eq!(name(5, 5), "world"); // the floor belongs to the world body
    let floor = model.id(ObjType::Geom, "floor").unwrap() as i32;
    assert_eq!(seg[5 * 96 + 5], floor);
    // RGB after a segmentation pass is normal colour again (flags restored).
    let f = r.render_named(&mut data, "top", 96, Channels::RGB).unwrap();
    let rgb = f.rgb.unwrap();
    let i = 3 * ((48 - 14) * 96 + 48);
    assert!(rgb[i] > 150 && rgb[i + 1] < 110, "{:?}", &rgb[i..i + 3]);
}

#[test]
fn several_cameras_and_sizes_from_one_renderer() {
    let (_m, mut data, mut r) = setup();
    let a = r.render_named(&mut data, "top", 32, Channels::RGB).unwrap();
    let b = r
        .render(
            &mut data,
            r.camera_id("top").unwrap(),
            128,
            64,
            Channels::RGB,
        )
        .unwrap();
    assert_eq!(a.rgb.unwrap().len(), 32 * 32 * 3);
    assert_eq!(
        (b.width, b.height, b.rgb.unwrap().len()),
        (128, 64, 128 * 64 * 3)
    );
}

#[test]
fn bad_camera_and_size_are_clear_errors() {
    let (_m, mut data, mut r) = setup();
    match r.render_named(&mut data, "nope", 64, Channels::RGB) {
        Err(RenderError::UnknownCamera { name, available }) => {
            assert_eq!(name, "nope");
            assert!(available.contains("top"));
        }
        other => panic!("{other:?}"),
    }
    let e = r
        .render_named(&mut data, "top", 256, Channels::RGB)
        .unwrap_err();
    assert!(e.to_string().contains("256x256"), "{e}");
    let e = r
        .render_named(&mut data, "top", 0, Channels::RGB)
        .unwrap_err();
    assert!(matches!(e, RenderError::BadSize { .. }));
}

#[test]
fn rendering_is_deterministic() {
    let (_m, mut data, mut r) = setup();
    let a = r.render_named(&mut data, "top", 64, Channels::ALL).unwrap();
    let b = r.render_named(&mut data, "top", 64, Channels::ALL).unwrap();
    assert_eq!(a, b);
}

#[test]
fn dropping_one_renderer_leaves_another_working() {
    let (model, mut data, mut a) = setup();
    let before = a.render_named(&mut data, "top", 64, Channels::RGB).unwrap();
    {
        let mut b = Renderer::new(&model, 64, 64, RenderQuality::default()).unwrap();
        let fb = b.render_named(&mut data, "top", 64, Channels::RGB).unwrap();
        assert_eq!(fb, before);
    }
    let after = a.render_named(&mut data, "top", 64, Channels::RGB).unwrap();
    assert_eq!(after, before);
    // Not a blank image either.
    let rgb = after.rgb.unwrap();
    assert!(rgb.iter().any(|&v| v > 200) && rgb.iter().any(|&v| v < 50));
}
