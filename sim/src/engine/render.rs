//! Offscreen rendering: EGL's surfaceless platform + MuJoCo's OpenGL renderer.
//!
//! The same code path runs on a CPU-only machine (Mesa llvmpipe) and on a GPU machine: EGL is opened at
//! run time (`libEGL.so.1`, libglvnd), a display is taken from `EGL_PLATFORM_SURFACELESS_MESA` (falling back
//! to the first `EGL_EXT_platform_device` device), a desktop-GL compatibility context is made current without
//! a surface, and MuJoCo draws into its own offscreen framebuffer. A [`Renderer`] is bound to the thread
//! that created it (GL contexts are per thread), so it is neither `Send` nor `Sync`.
//!
//! Frames come back **upright** (row 0 = top of the image), unlike OpenGL's bottom-up rows.

use std::ffi::{CStr, c_char, c_void};

use khronos_egl as egl;
use std::marker::PhantomData;

use crate::engine::mujoco::{Data, MjError, Model, ObjType, ffi, guard};

/// Errors from the renderer.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// EGL or OpenGL is missing or refused to give us a context.
    #[error(
        "offscreen OpenGL unavailable: {0}. Install EGL and Mesa's GL drivers with \
         `apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri libgl1` (on NVIDIA machines the driver's EGL \
         vendor library)"
    )]
    Gl(String),
    /// A camera name the model does not contain.
    #[error("unknown camera '{name}' (the model has: {available})")]
    UnknownCamera {
        /// The requested name.
        name: String,
        /// Comma-separated camera names of the model.
        available: String,
    },
    /// Width or height outside what the renderer was created for.
    #[error("bad image size {width}x{height}: {reason}")]
    BadSize {
        /// Requested width.
        width: usize,
        /// Requested height.
        height: usize,
        /// Why it was refused.
        reason: String,
    },
    /// MuJoCo raised an error while rendering.
    #[error(transparent)]
    Mujoco(#[from] MjError),
}

/// Result alias for this module.
pub type Result<T, E = RenderError> = std::result::Result<T, E>;

// --- EGL, loaded at run time ----------------------------------------------------------------------

/// EGL 1.4 entry points from the system's `libEGL.so.1`, opened at run time.
type Egl = egl::DynamicInstance<egl::EGL1_4>;

const EGL_PLATFORM_SURFACELESS_MESA: u32 = 0x31DD;
const EGL_PLATFORM_DEVICE_EXT: u32 = 0x313F;
const GL_VENDOR: u32 = 0x1F00;
const GL_RENDERER: u32 = 0x1F01;
const GL_VERSION: u32 = 0x1F02;

/// `eglGetPlatformDisplayEXT` (EGL_EXT_platform_base), found through `eglGetProcAddress`.
type FnGetPlatformDisplay =
    unsafe extern "C" fn(u32, *mut c_void, *const egl::Int) -> egl::EGLDisplay;
/// `eglQueryDevicesEXT` (EGL_EXT_device_enumeration).
type FnQueryDevices = unsafe extern "C" fn(egl::Int, *mut *mut c_void, *mut egl::Int) -> u32;
/// `glGetString`.
type FnGlGetString = unsafe extern "C" fn(u32) -> *const u8;

/// A current EGL + desktop-GL context with no window (one per thread).
struct GlContext {
    egl: Egl,
    display: egl::Display,
    context: egl::Context,
    info: GlInfo,
}

/// Which OpenGL implementation renders (for `sim info` and logs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GlInfo {
    /// `GL_VENDOR`.
    pub vendor: String,
    /// `GL_RENDERER` (e.g. "llvmpipe (LLVM 15.0.6, 256 bits)").
    pub renderer: String,
    /// `GL_VERSION`.
    pub version: String,
    /// The EGL platform used (`surfaceless` or `device`).
    pub platform: String,
}

fn cstr(p: *const c_char) -> String {
    if p.is_null() {
        String::new()
    } else {
        // SAFETY: EGL/GL return NUL-terminated static strings.
        unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
    }
}

/// The raw code of the thread's last EGL error (0x3000, `EGL_SUCCESS`, if none).
fn error_code(egl: &Egl) -> egl::Int {
    egl.get_error().map_or(egl::SUCCESS, |e| e.native())
}

/// Opens the EGL library `name` (the system's is `libEGL.so.1`, libglvnd's dispatcher); a missing
/// library is a [`RenderError::Gl`] that names the packages to install.
fn load_egl(name: &str) -> Result<Egl> {
    // SAFETY: an EGL library implements the EGL API the instance is typed with.
    unsafe { Egl::load_required_from_filename(name) }.map_err(|e| {
        RenderError::Gl(match e {
            egl::LoadError::Library(l) => format!("cannot open {name} ({l})"),
            other => format!("{name} is not usable ({other})"),
        })
    })
}

impl GlContext {
    fn new() -> Result<GlContext> {
        let egl = load_egl("libEGL.so.1")?;
        let client_ext = egl
            .query_string(None, egl::EXTENSIONS)
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let gpd = egl
            .get_proc_address("eglGetPlatformDisplayEXT")
            .ok_or_else(|| RenderError::Gl("EGL has no eglGetPlatformDisplayEXT".into()))?;
        // SAFETY: eglGetProcAddress returned eglGetPlatformDisplayEXT, whose C signature this is.
        let get_platform_display: FnGetPlatformDisplay = unsafe { std::mem::transmute(gpd) };
        // A display of `platform` for `native`, initialised; `None` if it cannot be had.
        let open = |platform: u32, native: *mut c_void| -> Option<egl::Display> {
            // SAFETY: a valid platform enum and native handle (null or a device from EGL).
            let d = unsafe { get_platform_display(platform, native, std::ptr::null()) };
            if d.is_null() {
                return None;
            }
            // SAFETY: a non-null display handle EGL just returned.
            let d = unsafe { egl::Display::from_ptr(d) };
            egl.initialize(d).ok().map(|_| d)
        };

        let mut attempts = Vec::new();
        let mut chosen = None;
        if client_ext.contains("EGL_MESA_platform_surfaceless") {
            match open(EGL_PLATFORM_SURFACELESS_MESA, std::ptr::null_mut()) {
                Some(d) => chosen = Some((d, "surfaceless")),
                None => attempts.push(format!(
                    "surfaceless platform failed (EGL error 0x{:x})",
                    error_code(&egl)
                )),
            }
        } else {
            attempts.push("no EGL_MESA_platform_surfaceless".to_string());
        }
        if chosen.is_none() && client_ext.contains("EGL_EXT_platform_device") {
            if let Some(qd) = egl.get_proc_address("eglQueryDevicesEXT") {
                // SAFETY: eglGetProcAddress returned eglQueryDevicesEXT, whose C signature this is.
                let query_devices: FnQueryDevices = unsafe { std::mem::transmute(qd) };
                let mut devices = [std::ptr::null_mut(); 16];
                let mut n = 0;
                // SAFETY: room for 16 device handles, and the count, as the call is told.
                if unsafe { query_devices(16, devices.as_mut_ptr(), &mut n) } != 0 {
                    chosen = devices
                        .iter()
                        .take(n.max(0) as usize)
                        .find_map(|&dev| open(EGL_PLATFORM_DEVICE_EXT, dev))
                        .map(|d| (d, "device"));
                }
            }
            if chosen.is_none() {
                attempts.push("no usable EGL device".to_string());
            }
        }
        let Some((display, platform)) = chosen else {
            return Err(RenderError::Gl(attempts.join("; ")));
        };

        let attribs = [
            egl::SURFACE_TYPE,
            egl::PBUFFER_BIT,
            egl::RENDERABLE_TYPE,
            egl::OPENGL_BIT,
            egl::RED_SIZE,
            8,
            egl::GREEN_SIZE,
            8,
            egl::BLUE_SIZE,
            8,
            egl::ALPHA_SIZE,
            8,
            egl::DEPTH_SIZE,
            24,
            egl::STENCIL_SIZE,
            8,
            egl::NONE,
        ];
        let Ok(Some(config)) = egl.choose_first_config(display, &attribs) else {
            return Err(RenderError::Gl("no EGL config with desktop OpenGL".into()));
        };
        if egl.bind_api(egl::OPENGL_API).is_err() {
            return Err(RenderError::Gl("eglBindAPI(EGL_OPENGL_API) failed".into()));
        }
        // Default attributes: a compatibility-profile context, which MuJoCo 2.2.2 needs.
        let context = egl
            .create_context(display, config, None, &[egl::NONE])
            .map_err(|e| {
                RenderError::Gl(format!("eglCreateContext failed (0x{:x})", e.native()))
            })?;
        if let Err(e) = egl.make_current(display, None, None, Some(context)) {
            let _ = egl.destroy_context(display, context);
            return Err(RenderError::Gl(format!(
                "eglMakeCurrent without a surface failed (0x{:x})",
                e.native()
            )));
        }
        let info = match egl.get_proc_address("glGetString") {
            None => GlInfo {
                vendor: egl
                    .query_string(Some(display), egl::VENDOR)
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default(),
                renderer: "unknown".into(),
                version: "unknown".into(),
                platform: platform.into(),
            },
            Some(gs) => {
                // SAFETY: eglGetProcAddress returned glGetString, whose C signature this is; a GL
                // context is current on this thread.
                let get_string: FnGlGetString = unsafe { std::mem::transmute(gs) };
                let s = |name| cstr(unsafe { get_string(name) } as *const c_char);
                GlInfo {
                    vendor: s(GL_VENDOR),
                    renderer: s(GL_RENDERER),
                    version: s(GL_VERSION),
                    platform: platform.into(),
                }
            }
        };
        Ok(GlContext {
            egl,
            display,
            context,
            info,
        })
    }

    fn make_current(&self) {
        let _ = self
            .egl
            .make_current(self.display, None, None, Some(self.context));
    }
}

impl Drop for GlContext {
    fn drop(&mut self) {
        // The display is shared by every context of the process (EGL hands out one display per platform),
        // so it is never terminated here: that would break other live renderers.
        // Release our context if it is current on this thread, then destroy it.
        if self.egl.get_current_context() == Some(self.context) {
            let _ = self.egl.make_current(self.display, None, None, None);
        }
        let _ = self.egl.destroy_context(self.display, self.context);
    }
}

// --- MuJoCo renderer -------------------------------------------------------------------------------

/// Rendering quality knobs. The defaults are the fast ones (all off), as used for datasets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct RenderQuality {
    /// Shadow maps from lights that cast shadows.
    pub shadows: bool,
    /// Multisample anti-aliasing samples (0 = off).
    pub msaa_samples: u32,
    /// Reflections on reflective materials.
    pub reflections: bool,
}

impl RenderQuality {
    /// MuJoCo's own defaults (shadows, 4× MSAA, reflections): prettier, ~20× slower on a CPU.
    pub fn high() -> Self {
        RenderQuality {
            shadows: true,
            msaa_samples: 4,
            reflections: true,
        }
    }
}

/// Which images to produce for one camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Channels {
    /// RGB, u8.
    pub rgb: bool,
    /// Depth in metres, f32.
    pub depth: bool,
    /// Per-pixel geom id (−1 = background).
    pub segmentation: bool,
}

impl Channels {
    /// RGB only.
    pub const RGB: Channels = Channels {
        rgb: true,
        depth: false,
        segmentation: false,
    };
    /// Everything.
    pub const ALL: Channels = Channels {
        rgb: true,
        depth: true,
        segmentation: true,
    };
}

/// One camera's images, upright (row 0 = top), row-major.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Frame {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// RGB bytes `[H, W, 3]`, if requested.
    pub rgb: Option<Vec<u8>>,
    /// Depth in metres `[H, W]` (distance along the camera axis), if requested.
    pub depth: Option<Vec<f32>>,
    /// Geom id per pixel `[H, W]`, −1 for background or non-geom elements, if requested.
    pub segmentation: Option<Vec<i32>>,
}

/// A visual-only cylinder added to every rendered frame (e.g. a stove burner's glow), world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decor {
    /// Centre.
    pub pos: [f64; 3],
    /// Orientation, row-major 3×3.
    pub mat: [f64; 9],
    /// Radius and half-height.
    pub size: [f64; 2],
    /// Colour.
    pub rgba: [f32; 4],
}

/// Renders named cameras of one model into CPU buffers.
pub struct Renderer {
    decor: Vec<Decor>,
    gl: GlContext,
    scene: Box<ffi::mjvScene>,
    context: Box<ffi::mjrContext>,
    option: ffi::mjvOption,
    perturb: ffi::mjvPerturb,
    quality: RenderQuality,
    max_width: usize,
    max_height: usize,
    camera_names: Vec<String>,
    rgb_buf: Vec<u8>,
    depth_buf: Vec<f32>,
    znear: f64,
    zfar: f64,
    _not_send: PhantomData<*mut ()>,
}

impl Renderer {
    /// Creates a renderer for `model` able to render images up to `max_width × max_height`.
    ///
    /// Geom group 0 (collision-only geoms) is hidden, as in LIBERO.
    pub fn new(
        model: &Model,
        max_width: usize,
        max_height: usize,
        quality: RenderQuality,
    ) -> Result<Renderer> {
        if max_width == 0 || max_height == 0 || max_width > 8192 || max_height > 8192 {
            return Err(RenderError::BadSize {
                width: max_width,
                height: max_height,
                reason: "sides must be between 1 and 8192 pixels".into(),
            });
        }
        crate::engine::mujoco::init()?;
        let _gl_guard = gl_lock();
        let gl = GlContext::new()?;
        // A shallow copy of the model struct (arrays shared, read-only) with our offscreen size and MSAA:
        // mjr_makeContext only reads it, and the shared model stays untouched.
        // SAFETY: mjModel is plain data; the copy is only read and is never freed.
        let mut view: ffi::mjModel = unsafe { std::ptr::read(model.raw()) };
        view.vis.global.offwidth = max_width as i32;
        view.vis.global.offheight = max_height as i32;
        view.vis.quality.offsamples = quality.msaa_samples as i32;

        let mut scene = Box::<ffi::mjvScene>::new_uninit();
        let mut context = Box::<ffi::mjrContext>::new_uninit();
        // SAFETY: default* initialise the structs; make* allocate their buffers; errors unwind into guard.
        let (scene, context) = unsafe {
            ffi::mjv_defaultScene(scene.as_mut_ptr());
            ffi::mjr_defaultContext(context.as_mut_ptr());
            let mut scene = scene.assume_init();
            let mut context = context.assume_init();
            let maxgeom = (2 * model.ngeom() + 200) as i32;
            let scn_ptr: *mut ffi::mjvScene = &mut *scene;
            guard(|| ffi::mjv_makeScene(model.ptr(), scn_ptr, maxgeom))?;
            let con_ptr: *mut ffi::mjrContext = &mut *context;
            let vptr: *const ffi::mjModel = &view;
            let made = guard(|| {
                ffi::mjr_makeContext(vptr, con_ptr, ffi::mjFONTSCALE_100 as i32);
                ffi::mjr_setBuffer(ffi::mjFB_OFFSCREEN as i32, con_ptr);
            });
            if let Err(e) = made {
                ffi::mjv_freeScene(scn_ptr);
                return Err(RenderError::Gl(format!(
                    "MuJoCo could not set up OpenGL: {e}"
                )));
            }
            if (context.offWidth as usize) < max_width || (context.offHeight as usize) < max_height
            {
                ffi::mjr_freeContext(con_ptr);
                ffi::mjv_freeScene(scn_ptr);
                return Err(RenderError::BadSize {
                    width: max_width,
                    height: max_height,
                    reason: "larger than the GL driver's offscreen buffer".into(),
                });
            }
            (scene, context)
        };
        let mut option = std::mem::MaybeUninit::<ffi::mjvOption>::uninit();
        let mut perturb = std::mem::MaybeUninit::<ffi::mjvPerturb>::uninit();
        // SAFETY: default* fully initialise the structs.
        let (mut option, perturb) = unsafe {
            ffi::mjv_defaultOption(option.as_mut_ptr());
            ffi::mjv_defaultPerturb(perturb.as_mut_ptr());
            (option.assume_init(), perturb.assume_init())
        };
        option.geomgroup[0] = 0;
        let extent = model.extent();
        let vis = &model.raw().vis.map;
        let mut r = Renderer {
            decor: Vec::new(),
            gl,
            scene,
            context,
            option,
            perturb,
            quality,
            max_width,
            max_height,
            camera_names: model.names(ObjType::Camera),
            rgb_buf: vec![0; 3 * max_width * max_height],
            depth_buf: vec![0.0; max_width * max_height],
            znear: vis.znear as f64 * extent,
            zfar: vis.zfar as f64 * extent,
            _not_send: PhantomData,
        };
        r.apply_quality();
        Ok(r)
    }

    fn apply_quality(&mut self) {
        let flags = &mut self.scene.flags;
        flags[ffi::mjRND_SHADOW as usize] = self.quality.shadows as u8;
        flags[ffi::mjRND_REFLECTION as usize] = self.quality.reflections as u8;
        flags[ffi::mjRND_SKYBOX as usize] = 0;
        flags[ffi::mjRND_SEGMENT as usize] = 0;
        flags[ffi::mjRND_IDCOLOR as usize] = 0;
    }

    /// The OpenGL implementation in use.
    pub fn gl_info(&self) -> &GlInfo {
        &self.gl.info
    }

    /// Shows or hides geom group `group` (0–5). Group 0 (collision-only geoms in LIBERO scenes) starts hidden.
    pub fn set_geom_group_visible(&mut self, group: usize, visible: bool) {
        if let Some(g) = self.option.geomgroup.get_mut(group) {
            *g = visible as u8;
        }
    }

    /// Replaces the decorations drawn in every following frame (not in segmentation).
    pub fn set_decor(&mut self, decor: Vec<Decor>) {
        self.decor = decor;
    }

    /// The quality settings in use.
    pub fn quality(&self) -> RenderQuality {
        self.quality
    }

    /// Largest image this renderer can produce.
    pub fn max_size(&self) -> (usize, usize) {
        (self.max_width, self.max_height)
    }

    /// Id of the named camera, or a clear error listing the model's cameras.
    pub fn camera_id(&self, name: &str) -> Result<usize> {
        self.camera_names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| RenderError::UnknownCamera {
                name: name.to_string(),
                available: self
                    .camera_names
                    .iter()
                    .filter(|n| !n.is_empty())
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    }

    /// Renders camera `camera` (an id from [`Renderer::camera_id`]) at `width × height`.
    ///
    /// `data` must be up to date (after `forward` or a step). Output rows are upright.
    pub fn render(
        &mut self,
        data: &mut Data,
        camera: usize,
        width: usize,
        height: usize,
        channels: Channels,
    ) -> Result<Frame> {
        if width == 0 || height == 0 || width > self.max_width || height > self.max_height {
            return Err(RenderError::BadSize {
                width,
                height,
                reason: format!(
                    "this renderer was made for at most {}x{}",
                    self.max_width, self.max_height
                ),
            });
        }
        if camera >= self.camera_names.len() {
            return Err(RenderError::UnknownCamera {
                name: format!("#{camera}"),
                available: self.camera_names.join(", "),
            });
        }
        let _gl_guard = gl_lock();
        self.gl.make_current();
        let mut cam = std::mem::MaybeUninit::<ffi::mjvCamera>::uninit();
        // SAFETY: mjv_defaultCamera initialises the struct.
        let mut cam = unsafe {
            ffi::mjv_defaultCamera(cam.as_mut_ptr());
            cam.assume_init()
        };
        cam.type_ = ffi::mjCAMERA_FIXED as i32;
        cam.fixedcamid = camera as i32;
        let viewport = ffi::mjrRect {
            left: 0,
            bottom: 0,
            width: width as i32,
            height: height as i32,
        };
        let m = data.model().ptr();
        let d = data.ptr();
        let scn: *mut ffi::mjvScene = &mut *self.scene;
        let con: *const ffi::mjrContext = &*self.context;
        let (opt, pert): (*const ffi::mjvOption, *const ffi::mjvPerturb) =
            (&self.option, &self.perturb);
        let n = width * height;
        // SAFETY: all pointers are valid; buffers hold max_width*max_height entries.
        unsafe {
            guard(|| ffi::mjv_updateScene(m, d, opt, pert, &mut cam, ffi::mjCAT_ALL as i32, scn))?;
        }
        let mut frame = Frame {
            width,
            height,
            ..Frame::default()
        };
        let base_ngeom = self.scene.ngeom;
        for d in &self.decor {
            if self.scene.ngeom >= self.scene.maxgeom {
                break;
            }
            let size = [d.size[0], d.size[0], d.size[1]];
            // SAFETY: ngeom < maxgeom, so the slot exists; mjv_initGeom fills it.
            unsafe {
                let g = self.scene.geoms.add(self.scene.ngeom as usize);
                ffi::mjv_initGeom(
                    g,
                    ffi::mjGEOM_CYLINDER as i32,
                    size.as_ptr(),
                    d.pos.as_ptr(),
                    d.mat.as_ptr(),
                    d.rgba.as_ptr(),
                );
                (*g).category = ffi::mjCAT_DECOR as i32;
            }
            self.scene.ngeom += 1;
        }
        if channels.rgb || channels.depth {
            let depth_ptr = if channels.depth {
                self.depth_buf.as_mut_ptr()
            } else {
                std::ptr::null_mut()
            };
            let rgb_ptr = if channels.rgb {
                self.rgb_buf.as_mut_ptr()
            } else {
                std::ptr::null_mut()
            };
            // SAFETY: as above.
            unsafe {
                guard(|| {
                    ffi::mjr_render(viewport, scn, con);
                    ffi::mjr_readPixels(rgb_ptr, depth_ptr, viewport, con);
                })?;
            }
            if channels.rgb {
                frame.rgb = Some(flip_rows(&self.rgb_buf[..3 * n], width, height, 3));
            }
            if channels.depth {
                let (near, far) = (self.znear, self.zfar);
                let lin: Vec<f32> = self.depth_buf[..n]
                    .iter()
                    .map(|&z| (near / (1.0 - z as f64 * (1.0 - near / far))) as f32)
                    .collect();
                frame.depth = Some(flip_rows(&lin, width, height, 1));
            }
        }
        // Decorations are visual only: segmentation and later frames see the plain scene.
        self.scene.ngeom = base_ngeom;
        if channels.segmentation {
            self.scene.flags[ffi::mjRND_SEGMENT as usize] = 1;
            self.scene.flags[ffi::mjRND_IDCOLOR as usize] = 1;
            // SAFETY: as above.
            let r = unsafe {
                guard(|| {
                    ffi::mjr_render(viewport, scn, con);
                    ffi::mjr_readPixels(
                        self.rgb_buf.as_mut_ptr(),
                        std::ptr::null_mut(),
                        viewport,
                        con,
                    );
                })
            };
            self.scene.flags[ffi::mjRND_SEGMENT as usize] = 0;
            self.scene.flags[ffi::mjRND_IDCOLOR as usize] = 0;
            r?;
            let ngeom = self.scene.ngeom.max(0) as usize;
            // SAFETY: the scene holds `ngeom` valid entries after mjv_updateScene.
            let geoms = unsafe { std::slice::from_raw_parts(self.scene.geoms, ngeom) };
            let ids: Vec<i32> = self.rgb_buf[..3 * n]
                .chunks_exact(3)
                .map(|p| {
                    let seg = p[0] as i64 + 256 * p[1] as i64 + 65536 * p[2] as i64 - 1;
                    if seg < 0 || seg as usize >= ngeom {
                        return -1;
                    }
                    let g = &geoms[seg as usize];
                    if g.objtype == ffi::mjOBJ_GEOM as i32 {
                        g.objid
                    } else {
                        -1
                    }
                })
                .collect();
            frame.segmentation = Some(flip_rows(&ids, width, height, 1));
        }
        Ok(frame)
    }

    /// Raw scene, context, option and perturbation pointers (for the bare-FFI benchmark), with the GL
    /// context made current.
    pub(crate) fn raw_parts(
        &mut self,
    ) -> (
        *mut ffi::mjvScene,
        *const ffi::mjrContext,
        *const ffi::mjvOption,
        *const ffi::mjvPerturb,
    ) {
        self.gl.make_current();
        (
            &mut *self.scene,
            &*self.context,
            &self.option,
            &self.perturb,
        )
    }

    /// Convenience: render camera `name` at `size × size`.
    pub fn render_named(
        &mut self,
        data: &mut Data,
        name: &str,
        size: usize,
        channels: Channels,
    ) -> Result<Frame> {
        let id = self.camera_id(name)?;
        self.render(data, id, size, size, channels)
    }
}

impl Drop for Renderer {
    fn drop(&mut self) {
        let _gl_guard = gl_lock();
        self.gl.make_current();
        // SAFETY: both were allocated in `new`; freed once, with the context current.
        unsafe {
            ffi::mjr_freeContext(&mut *self.context);
            ffi::mjv_freeScene(&mut *self.scene);
        }
    }
}

/// One GL caller at a time, process-wide. Every renderer has its own context, but all of them live on
/// one EGL display, i.e. one Mesa screen, and llvmpipe crashed (SIGSEGV under `mjr_readPixels`) when two
/// simulator threads rendered at the same moment (seen while generating T3 with 2 workers). Context
/// creation, rendering and freeing are therefore serialised; physics stays parallel, and llvmpipe still
/// rasterises each frame on its own threads.
fn gl_lock() -> std::sync::MutexGuard<'static, ()> {
    static GL: std::sync::Mutex<()> = std::sync::Mutex::new(());
    GL.lock().unwrap_or_else(|p| p.into_inner())
}

/// Reverses the row order of a `[height, width, channels]` buffer (OpenGL rows are bottom-up).
pub fn flip_rows<T: Copy>(buf: &[T], width: usize, height: usize, channels: usize) -> Vec<T> {
    let row = width * channels;
    assert_eq!(
        buf.len(),
        row * height,
        "buffer is not [height, width, channels]"
    );
    let mut out = Vec::with_capacity(buf.len());
    for r in (0..height).rev() {
        out.extend_from_slice(&buf[r * row..(r + 1) * row]);
    }
    out
}

/// Maps a geom-id segmentation image to body ids (−1 stays −1).
pub fn geoms_to_bodies(model: &Model, seg: &[i32]) -> Vec<i32> {
    seg.iter()
        .map(|&g| {
            if g < 0 {
                -1
            } else {
                model.geom_body(g as usize) as i32
            }
        })
        .collect()
}

/// Writes an RGB frame as PNG (the path is written atomically: temporary name, then rename).
pub fn save_png(frame: &Frame, path: &std::path::Path) -> std::io::Result<()> {
    let rgb = frame
        .rgb
        .as_ref()
        .ok_or_else(|| std::io::Error::other("frame has no RGB image"))?;
    let img = image::RgbImage::from_raw(frame.width as u32, frame.height as u32, rgb.clone())
        .ok_or_else(|| std::io::Error::other("RGB buffer does not match the frame size"))?;
    data::fsio::write_png(path, &img).map_err(|e| match e {
        data::DataError::Io { source, .. } => source,
        other => std::io::Error::other(other),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flip_rows_reverses_rows() {
        let b = [1, 2, 3, 4, 5, 6];
        assert_eq!(flip_rows(&b, 2, 3, 1), vec![5, 6, 3, 4, 1, 2]);
        assert_eq!(flip_rows(&b, 1, 2, 3), vec![4, 5, 6, 1, 2, 3]);
    }

    /// Without EGL, the error names the library and the packages that provide it.
    #[test]
    fn missing_egl_names_the_packages_to_install() {
        let Err(e) = load_egl("libEGL-not-installed.so.1") else {
            panic!("a missing library loaded");
        };
        let m = e.to_string();
        assert!(m.contains("cannot open libEGL-not-installed.so.1"), "{m}");
        assert!(m.contains("apt-get install libegl1 libegl-mesa0"), "{m}");
    }
}
