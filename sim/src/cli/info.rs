//! `sim info`: the MuJoCo version and the OpenGL renderer in use.

use sim::env::minimal_scene_xml;
use sim::mujoco::{self, Model};
use sim::render::{RenderQuality, Renderer};

/// Prints the MuJoCo version, the EGL platform and GL strings, and the minimal scene's sizes.
pub fn run() -> anyhow::Result<()> {
    mujoco::init()?;
    data::outln!("mujoco_version: {}", mujoco::version());
    let model = Model::from_xml_str(&minimal_scene_xml())?;
    let r = Renderer::new(&model, 64, 64, RenderQuality::default())?;
    let gl = r.gl_info();
    data::outln!("egl_platform: {}", gl.platform);
    data::outln!("gl_vendor: {}", gl.vendor);
    data::outln!("gl_renderer: {}", gl.renderer);
    data::outln!("gl_version: {}", gl.version);
    data::outln!(
        "scene: nq {} nv {} nu {} ngeom {}",
        model.nq(),
        model.nv(),
        model.nu(),
        model.ngeom()
    );
    Ok(())
}
