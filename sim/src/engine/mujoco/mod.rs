//! Safe layer over Debian's MuJoCo 2.2.2 (`libmujoco-dev`), the only place that owns raw MuJoCo pointers.
//!
//! [`Model`] is the compiled, constant model (shared through `Arc`); [`Data`] is one simulation state.
//! MuJoCo's error hook is replaced process-wide on first use: an engine error unwinds back to the
//! nearest safe call and becomes [`MjError::Engine`] instead of MuJoCo's default "Press Enter to exit"
//! handler, and warnings are collected in memory (see [`take_warnings`]) instead of `MUJOCO_LOG.TXT`.

#[allow(
    non_upper_case_globals,
    non_camel_case_types,
    non_snake_case,
    dead_code,
    clippy::all,
    missing_docs,
    unsafe_op_in_unsafe_fn
)]
pub mod ffi;

use std::ffi::{CStr, CString, c_char, c_int};
use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::path::Path;
use std::ptr::NonNull;
use std::sync::{Arc, Mutex, Once};

/// Version number this crate was written against (`mj_version()` of Debian's 2.2.2).
pub const MJ_VERSION: i32 = 222;

/// Errors raised by the MuJoCo layer.
#[derive(Debug, thiserror::Error)]
pub enum MjError {
    /// The XML could not be parsed or compiled; `message` is MuJoCo's own text.
    #[error("{source_name}: MuJoCo could not load the model: {message}")]
    Load {
        /// File path or `<string>` for in-memory XML.
        source_name: String,
        /// MuJoCo's error message.
        message: String,
    },
    /// MuJoCo's engine raised `mju_error` (caught by our hook).
    #[error("MuJoCo error: {0}")]
    Engine(String),
    /// A name that the model does not contain.
    #[error("the model has no {kind} named '{name}'")]
    UnknownName {
        /// Object kind (body, site, …).
        kind: &'static str,
        /// The missing name.
        name: String,
    },
    /// The linked library is not the version this crate was written against.
    #[error(
        "libmujoco reports version {found}, this crate needs {expected} (Debian's libmujoco-dev 2.2.2)"
    )]
    Version {
        /// `mj_version()` of the loaded library.
        found: i32,
        /// Expected version.
        expected: i32,
    },
    /// Invalid argument to a safe wrapper.
    #[error("{0}")]
    Invalid(String),
}

/// Result alias for this module.
pub type Result<T, E = MjError> = std::result::Result<T, E>;

/// Payload carried by the unwinding started in [`error_hook`].
struct EnginePanic(String);

static HOOKS: Once = Once::new();
static WARNINGS: Mutex<Vec<String>> = Mutex::new(Vec::new());

unsafe extern "C-unwind" fn error_hook(msg: *const c_char) {
    let text = if msg.is_null() {
        String::from("unknown MuJoCo error")
    } else {
        // SAFETY: MuJoCo passes a NUL-terminated message.
        unsafe { CStr::from_ptr(msg) }
            .to_string_lossy()
            .into_owned()
    };
    // Unwind (without running the panic hook) back to the `guard` around the FFI call.
    resume_unwind(Box::new(EnginePanic(text)));
}

unsafe extern "C-unwind" fn warning_hook(msg: *const c_char) {
    if msg.is_null() {
        return;
    }
    // SAFETY: MuJoCo passes a NUL-terminated message.
    let text = unsafe { CStr::from_ptr(msg) }
        .to_string_lossy()
        .into_owned();
    if let Ok(mut w) = WARNINGS.lock()
        && w.len() < 1000
    {
        w.push(text);
    }
}

/// Installs the error and warning hooks once per process and checks the library version.
pub fn init() -> Result<()> {
    HOOKS.call_once(|| {
        // SAFETY: the hooks are plain global function pointers; we set them once before any use.
        unsafe {
            ffi::mju_user_error = Some(error_hook);
            ffi::mju_user_warning = Some(warning_hook);
        }
    });
    let found = version();
    if found != MJ_VERSION {
        return Err(MjError::Version {
            found,
            expected: MJ_VERSION,
        });
    }
    Ok(())
}

/// `mj_version()` of the linked library (222 for 2.2.2).
pub fn version() -> i32 {
    // SAFETY: no arguments, no state.
    unsafe { ffi::mj_version() }
}

/// Warnings MuJoCo raised since the last call (drained).
pub fn take_warnings() -> Vec<String> {
    WARNINGS
        .lock()
        .map(|mut w| std::mem::take(&mut *w))
        .unwrap_or_default()
}

/// Runs `f`, turning an `mju_error` raised inside it into [`MjError::Engine`].
pub(crate) fn guard<T>(f: impl FnOnce() -> T) -> Result<T> {
    init()?;
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(v) => Ok(v),
        Err(payload) => match payload.downcast::<EnginePanic>() {
            Ok(e) => Err(MjError::Engine(e.0)),
            Err(other) => resume_unwind(other),
        },
    }
}

/// Kinds of named model objects (`mjtObj`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjType {
    /// `mjOBJ_BODY`
    Body,
    /// `mjOBJ_JOINT`
    Joint,
    /// `mjOBJ_GEOM`
    Geom,
    /// `mjOBJ_SITE`
    Site,
    /// `mjOBJ_CAMERA`
    Camera,
    /// `mjOBJ_ACTUATOR`
    Actuator,
    /// `mjOBJ_LIGHT`
    Light,
}

impl ObjType {
    fn raw(self) -> c_int {
        (match self {
            ObjType::Body => ffi::mjOBJ_BODY,
            ObjType::Joint => ffi::mjOBJ_JOINT,
            ObjType::Geom => ffi::mjOBJ_GEOM,
            ObjType::Site => ffi::mjOBJ_SITE,
            ObjType::Camera => ffi::mjOBJ_CAMERA,
            ObjType::Actuator => ffi::mjOBJ_ACTUATOR,
            ObjType::Light => ffi::mjOBJ_LIGHT,
        }) as c_int
    }

    fn label(self) -> &'static str {
        match self {
            ObjType::Body => "body",
            ObjType::Joint => "joint",
            ObjType::Geom => "geom",
            ObjType::Site => "site",
            ObjType::Camera => "camera",
            ObjType::Actuator => "actuator",
            ObjType::Light => "light",
        }
    }
}

/// A compiled MuJoCo model (`mjModel`). Constant after loading; share it with `Arc`.
pub struct Model {
    raw: NonNull<ffi::mjModel>,
}

// SAFETY: an mjModel is plain heap memory that MuJoCo only reads during simulation; all mutation
// goes through `&mut Model`.
unsafe impl Send for Model {}
// SAFETY: as above, shared access is read-only.
unsafe impl Sync for Model {}

impl Drop for Model {
    fn drop(&mut self) {
        // SAFETY: we own the pointer, allocated by mj_loadXML.
        unsafe { ffi::mj_deleteModel(self.raw.as_ptr()) }
    }
}

/// Heap-allocated virtual file system (`mjVFS` is ~2 MB: never on the stack).
struct Vfs {
    raw: Box<std::mem::MaybeUninit<ffi::mjVFS>>,
}

impl Vfs {
    fn new() -> Self {
        let mut raw = Box::<ffi::mjVFS>::new_uninit();
        // SAFETY: mj_defaultVFS initialises every field it later reads (nfile = 0).
        unsafe { ffi::mj_defaultVFS(raw.as_mut_ptr()) };
        Vfs { raw }
    }

    fn ptr(&mut self) -> *mut ffi::mjVFS {
        self.raw.as_mut_ptr()
    }

    /// Adds an in-memory file under `name` (a bare file name, no directories).
    fn add(&mut self, name: &str, bytes: &[u8]) -> Result<()> {
        if name.len() >= ffi::mjMAXVFSNAME as usize || name.contains('/') {
            return Err(MjError::Invalid(format!("bad virtual file name '{name}'")));
        }
        let size = c_int::try_from(bytes.len())
            .map_err(|_| MjError::Invalid(format!("virtual file '{name}' is too large")))?;
        let cname =
            CString::new(name).map_err(|_| MjError::Invalid(format!("bad name '{name}'")))?;
        let vfs = self.ptr();
        // SAFETY: vfs is initialised; MuJoCo allocates `size` bytes for the new file.
        let rc = unsafe { ffi::mj_makeEmptyFileVFS(vfs, cname.as_ptr(), size) };
        match rc {
            0 => {}
            1 => {
                return Err(MjError::Invalid(
                    "MuJoCo's virtual file system is full".into(),
                ));
            }
            2 => {
                return Err(MjError::Invalid(format!(
                    "virtual file '{name}' added twice"
                )));
            }
            _ => {
                return Err(MjError::Invalid(format!(
                    "could not add virtual file '{name}'"
                )));
            }
        }
        // SAFETY: the file was just created, so mj_findFileVFS returns its index, whose buffer holds `size` bytes.
        unsafe {
            let i = ffi::mj_findFileVFS(vfs, cname.as_ptr());
            if i < 0 {
                return Err(MjError::Invalid(format!("virtual file '{name}' vanished")));
            }
            let dst = (*vfs).filedata[i as usize] as *mut u8;
            if !bytes.is_empty() {
                std::ptr::copy_nonoverlapping(bytes.as_ptr(), dst, bytes.len());
            }
        }
        Ok(())
    }
}

impl Drop for Vfs {
    fn drop(&mut self) {
        // SAFETY: initialised in `new`; frees the file buffers MuJoCo allocated.
        unsafe { ffi::mj_deleteVFS(self.ptr()) }
    }
}

fn load(path: &CStr, vfs: Option<&mut Vfs>, source_name: &str) -> Result<Model> {
    let mut err = vec![0 as c_char; 1024];
    let vfs_ptr = vfs.map_or(std::ptr::null(), |v| v.ptr() as *const _);
    let raw = guard(|| {
        // SAFETY: path is NUL-terminated; err has the size we pass.
        unsafe { ffi::mj_loadXML(path.as_ptr(), vfs_ptr, err.as_mut_ptr(), err.len() as c_int) }
    })?;
    match NonNull::new(raw) {
        Some(raw) => Ok(Model { raw }),
        None => {
            // SAFETY: MuJoCo NUL-terminates the message within the buffer.
            let message = unsafe { CStr::from_ptr(err.as_ptr()) }
                .to_string_lossy()
                .trim()
                .to_string();
            Err(MjError::Load {
                source_name: source_name.to_string(),
                message: if message.is_empty() {
                    "unknown error".into()
                } else {
                    message
                },
            })
        }
    }
}

impl Model {
    /// Loads and compiles an MJCF file from disk (assets resolved relative to its folder).
    pub fn from_xml_file(path: impl AsRef<Path>) -> Result<Model> {
        let path = path.as_ref();
        let name = path.display().to_string();
        if !path.is_file() {
            return Err(MjError::Load {
                source_name: name,
                message: "no such file".into(),
            });
        }
        let c = CString::new(path.as_os_str().as_encoded_bytes()).map_err(|_| MjError::Load {
            source_name: name.clone(),
            message: "path contains a NUL byte".into(),
        })?;
        load(&c, None, &name)
    }

    /// Loads and compiles MJCF held in memory (through MuJoCo's virtual file system).
    pub fn from_xml_str(xml: &str) -> Result<Model> {
        Self::from_xml_str_with_assets(xml, &[])
    }

    /// Loads MJCF from memory together with in-memory asset files (meshes, textures) it refers to
    /// by bare file name.
    pub fn from_xml_str_with_assets(xml: &str, assets: &[(&str, &[u8])]) -> Result<Model> {
        const MAIN: &str = "__model__.xml";
        let mut vfs = Vfs::new();
        vfs.add(MAIN, xml.as_bytes())?;
        for (name, bytes) in assets {
            vfs.add(name, bytes)?;
        }
        let c = CString::new(MAIN).expect("constant has no NUL");
        load(&c, Some(&mut vfs), "<string>").map_err(|e| match e {
            MjError::Load { message, .. } => MjError::Load {
                source_name: "<in-memory MJCF>".into(),
                message: message.replace(MAIN, "<in-memory MJCF>"),
            },
            other => other,
        })
    }

    /// Raw read access for the other modules of this crate.
    pub(crate) fn raw(&self) -> &ffi::mjModel {
        // SAFETY: valid for the lifetime of self.
        unsafe { self.raw.as_ref() }
    }

    pub(crate) fn ptr(&self) -> *const ffi::mjModel {
        self.raw.as_ptr()
    }

    /// Number of generalized coordinates.
    pub fn nq(&self) -> usize {
        self.raw().nq as usize
    }
    /// Number of degrees of freedom.
    pub fn nv(&self) -> usize {
        self.raw().nv as usize
    }
    /// Number of actuators.
    pub fn nu(&self) -> usize {
        self.raw().nu as usize
    }
    /// Number of bodies, world included.
    pub fn nbody(&self) -> usize {
        self.raw().nbody as usize
    }
    /// Number of geoms.
    pub fn ngeom(&self) -> usize {
        self.raw().ngeom as usize
    }
    /// Number of sites.
    pub fn nsite(&self) -> usize {
        self.raw().nsite as usize
    }
    /// Number of cameras.
    pub fn ncam(&self) -> usize {
        self.raw().ncam as usize
    }
    /// Physics time step in seconds.
    pub fn timestep(&self) -> f64 {
        self.raw().opt.timestep
    }

    /// Id of the named object, if present.
    pub fn id(&self, kind: ObjType, name: &str) -> Option<usize> {
        let c = CString::new(name).ok()?;
        // SAFETY: valid model and NUL-terminated name.
        let id = unsafe { ffi::mj_name2id(self.ptr(), kind.raw(), c.as_ptr()) };
        (id >= 0).then_some(id as usize)
    }

    /// Id of the named object, or [`MjError::UnknownName`].
    pub fn require(&self, kind: ObjType, name: &str) -> Result<usize> {
        self.id(kind, name).ok_or_else(|| MjError::UnknownName {
            kind: kind.label(),
            name: name.to_string(),
        })
    }

    /// Name of object `id`, if it has one.
    pub fn name(&self, kind: ObjType, id: usize) -> Option<&str> {
        // SAFETY: mj_id2name returns NULL or a pointer into the model's name buffer.
        let p = unsafe { ffi::mj_id2name(self.ptr(), kind.raw(), id as c_int) };
        if p.is_null() {
            return None;
        }
        // SAFETY: NUL-terminated string that lives as long as the model.
        unsafe { CStr::from_ptr(p) }
            .to_str()
            .ok()
            .filter(|s| !s.is_empty())
    }

    /// Names of all objects of one kind (unnamed ones as empty strings), indexed by id.
    pub fn names(&self, kind: ObjType) -> Vec<String> {
        let n = match kind {
            ObjType::Body => self.nbody(),
            ObjType::Joint => self.raw().njnt as usize,
            ObjType::Geom => self.ngeom(),
            ObjType::Site => self.nsite(),
            ObjType::Camera => self.ncam(),
            ObjType::Actuator => self.nu(),
            ObjType::Light => self.raw().nlight as usize,
        };
        (0..n)
            .map(|i| self.name(kind, i).unwrap_or_default().to_string())
            .collect()
    }

    /// Body that owns geom `geom`.
    pub fn geom_body(&self, geom: usize) -> usize {
        assert!(geom < self.ngeom(), "geom id out of range");
        // SAFETY: index checked above; array has ngeom entries.
        unsafe { *self.raw().geom_bodyid.add(geom) as usize }
    }

    /// Top-level ancestor of `body` below the world (the body itself if it is top-level; 0 for the world).
    pub fn body_root(&self, body: usize) -> usize {
        assert!(body < self.nbody(), "body id out of range");
        // SAFETY: index checked; array has nbody entries.
        unsafe { *self.raw().body_rootid.add(body) as usize }
    }

    /// Parent of `body` (0 for the world itself).
    pub fn body_parent(&self, body: usize) -> usize {
        assert!(body < self.nbody(), "body id out of range");
        // SAFETY: index checked; array has nbody entries.
        unsafe { *self.raw().body_parentid.add(body) as usize }
    }

    /// qpos address of joint `joint`.
    pub fn joint_qpos_adr(&self, joint: usize) -> usize {
        assert!(joint < self.raw().njnt as usize, "joint id out of range");
        // SAFETY: index checked.
        unsafe { *self.raw().jnt_qposadr.add(joint) as usize }
    }

    /// qvel (dof) address of joint `joint`.
    pub fn joint_dof_adr(&self, joint: usize) -> usize {
        assert!(joint < self.raw().njnt as usize, "joint id out of range");
        // SAFETY: index checked.
        unsafe { *self.raw().jnt_dofadr.add(joint) as usize }
    }

    /// Range `[lo, hi]` of joint `joint`.
    pub fn joint_range(&self, joint: usize) -> [f64; 2] {
        assert!(joint < self.raw().njnt as usize, "joint id out of range");
        // SAFETY: index checked; two entries per joint.
        unsafe {
            let p = self.raw().jnt_range.add(2 * joint);
            [*p, *p.add(1)]
        }
    }

    /// Control range `[lo, hi]` of actuator `act`.
    pub fn actuator_ctrl_range(&self, act: usize) -> [f64; 2] {
        assert!(act < self.nu(), "actuator id out of range");
        // SAFETY: index checked; two entries per actuator.
        unsafe {
            let p = self.raw().actuator_ctrlrange.add(2 * act);
            [*p, *p.add(1)]
        }
    }

    /// Body that carries site `site`.
    pub fn site_body(&self, site: usize) -> usize {
        assert!(site < self.nsite(), "site id out of range");
        // SAFETY: index checked.
        unsafe { *self.raw().site_bodyid.add(site) as usize }
    }

    /// Half-sizes of site `site` (its MJCF `size`).
    pub fn site_size(&self, site: usize) -> [f64; 3] {
        assert!(site < self.nsite(), "site id out of range");
        // SAFETY: index checked; three entries per site.
        unsafe {
            let p = self.raw().site_size.add(3 * site);
            [*p, *p.add(1), *p.add(2)]
        }
    }

    /// Body that carries joint `joint`.
    pub fn joint_body(&self, joint: usize) -> usize {
        assert!(joint < self.njnt(), "joint id out of range");
        // SAFETY: index checked.
        unsafe { *self.raw().jnt_bodyid.add(joint) as usize }
    }

    /// Number of joints.
    pub fn njnt(&self) -> usize {
        self.raw().njnt as usize
    }

    /// Mocap index of `body`, if it is a mocap body.
    pub fn body_mocap(&self, body: usize) -> Option<usize> {
        assert!(body < self.nbody(), "body id out of range");
        // SAFETY: index checked.
        let id = unsafe { *self.raw().body_mocapid.add(body) };
        (id >= 0).then_some(id as usize)
    }

    /// Number of mocap bodies.
    pub fn nmocap(&self) -> usize {
        self.raw().nmocap as usize
    }

    /// Vertical field of view of camera `cam` in degrees.
    pub fn camera_fovy(&self, cam: usize) -> f64 {
        assert!(cam < self.ncam(), "camera id out of range");
        // SAFETY: index checked.
        unsafe { *self.raw().cam_fovy.add(cam) }
    }

    /// Spatial extent used by the renderer's clipping planes.
    pub fn extent(&self) -> f64 {
        self.raw().stat.extent
    }
}

/// A contact between two geoms (`mjContact`, the fields we use).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// First geom id.
    pub geom1: usize,
    /// Second geom id.
    pub geom2: usize,
    /// Signed distance (negative: penetration), metres.
    pub dist: f64,
    /// Contact point, world frame.
    pub pos: [f64; 3],
    /// Contact normal (first row of the contact frame), world frame.
    pub normal: [f64; 3],
}

/// One simulation state (`mjData`) for a shared [`Model`].
pub struct Data {
    model: Arc<Model>,
    raw: NonNull<ffi::mjData>,
}

// SAFETY: mjData is plain heap memory owned by this value; MuJoCo keeps no thread-local state for it.
unsafe impl Send for Data {}

impl Drop for Data {
    fn drop(&mut self) {
        // SAFETY: allocated by mj_makeData for this model; freed once.
        unsafe { ffi::mj_deleteData(self.raw.as_ptr()) }
    }
}

macro_rules! slice_accessors {
    ($( $(#[$doc:meta])* $name:ident, $name_mut:ident, $field:ident, $ty:ty, $len:expr; )*) => {
        $(
            $(#[$doc])*
            pub fn $name(&self) -> &[$ty] {
                let n = { let m = self.model.raw(); $len(m) };
                // SAFETY: MuJoCo allocates exactly this many entries for the model.
                unsafe { std::slice::from_raw_parts(self.raw().$field, n) }
            }
            $(#[$doc])*
            pub fn $name_mut(&mut self) -> &mut [$ty] {
                let n = { let m = self.model.raw(); $len(m) };
                // SAFETY: as above, and `&mut self` makes the borrow unique.
                unsafe { std::slice::from_raw_parts_mut(self.raw_mut().$field, n) }
            }
        )*
    };
}

impl Data {
    /// Allocates a state for `model`, at the model's reference configuration.
    pub fn new(model: Arc<Model>) -> Result<Data> {
        let raw = guard(|| {
            // SAFETY: valid model.
            unsafe { ffi::mj_makeData(model.ptr()) }
        })?;
        let raw = NonNull::new(raw).ok_or_else(|| MjError::Engine("mj_makeData failed".into()))?;
        Ok(Data { model, raw })
    }

    /// The model this state belongs to.
    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }

    pub(crate) fn raw(&self) -> &ffi::mjData {
        // SAFETY: valid for self's lifetime.
        unsafe { self.raw.as_ref() }
    }

    pub(crate) fn raw_mut(&mut self) -> &mut ffi::mjData {
        // SAFETY: valid, uniquely borrowed.
        unsafe { self.raw.as_mut() }
    }

    pub(crate) fn ptr(&mut self) -> *mut ffi::mjData {
        self.raw.as_ptr()
    }

    /// Resets to the model's reference configuration (`mj_resetData`).
    pub fn reset(&mut self) {
        let (m, d) = (self.model.ptr(), self.raw.as_ptr());
        // SAFETY: valid pointers; reset cannot raise errors.
        unsafe { ffi::mj_resetData(m, d) }
    }

    /// One physics step (`mj_step`).
    pub fn step(&mut self) -> Result<()> {
        let (m, d) = (self.model.ptr(), self.raw.as_ptr());
        // SAFETY: valid pointers.
        guard(|| unsafe { ffi::mj_step(m, d) })
    }

    /// First half of a step: positions and velocities (`mj_step1`), so controls can depend on them.
    pub fn step1(&mut self) -> Result<()> {
        let (m, d) = (self.model.ptr(), self.raw.as_ptr());
        // SAFETY: valid pointers.
        guard(|| unsafe { ffi::mj_step1(m, d) })
    }

    /// Second half of a step: actuation, acceleration and integration (`mj_step2`).
    pub fn step2(&mut self) -> Result<()> {
        let (m, d) = (self.model.ptr(), self.raw.as_ptr());
        // SAFETY: valid pointers.
        guard(|| unsafe { ffi::mj_step2(m, d) })
    }

    /// Recomputes every derived quantity without advancing time (`mj_forward`).
    pub fn forward(&mut self) -> Result<()> {
        let (m, d) = (self.model.ptr(), self.raw.as_ptr());
        // SAFETY: valid pointers.
        guard(|| unsafe { ffi::mj_forward(m, d) })
    }

    /// Simulation time in seconds.
    pub fn time(&self) -> f64 {
        self.raw().time
    }

    slice_accessors! {
        /// Generalized positions `[nq]`.
        qpos, qpos_mut, qpos, f64, |m: &ffi::mjModel| m.nq as usize;
        /// Generalized velocities `[nv]`.
        qvel, qvel_mut, qvel, f64, |m: &ffi::mjModel| m.nv as usize;
        /// Actuator controls `[nu]`.
        ctrl, ctrl_mut, ctrl, f64, |m: &ffi::mjModel| m.nu as usize;
        /// Bias forces (Coriolis, centrifugal, gravity) `[nv]`.
        qfrc_bias, qfrc_bias_mut, qfrc_bias, f64, |m: &ffi::mjModel| m.nv as usize;
        /// Applied generalized forces `[nv]`.
        qfrc_applied, qfrc_applied_mut, qfrc_applied, f64, |m: &ffi::mjModel| m.nv as usize;
        /// Warm-start accelerations `[nv]`.
        qacc_warmstart, qacc_warmstart_mut, qacc_warmstart, f64, |m: &ffi::mjModel| m.nv as usize;
        /// Body positions `[nbody * 3]`.
        xpos, xpos_mut, xpos, f64, |m: &ffi::mjModel| 3 * m.nbody as usize;
        /// Body orientations as quaternions wxyz `[nbody * 4]`.
        xquat, xquat_mut, xquat, f64, |m: &ffi::mjModel| 4 * m.nbody as usize;
        /// Site positions `[nsite * 3]`.
        site_xpos, site_xpos_mut, site_xpos, f64, |m: &ffi::mjModel| 3 * m.nsite as usize;
        /// Site orientations, row-major 3×3 `[nsite * 9]`.
        site_xmat, site_xmat_mut, site_xmat, f64, |m: &ffi::mjModel| 9 * m.nsite as usize;
        /// Mocap body positions `[nmocap * 3]`.
        mocap_pos, mocap_pos_mut, mocap_pos, f64, |m: &ffi::mjModel| 3 * m.nmocap as usize;
        /// Mocap body orientations, wxyz `[nmocap * 4]`.
        mocap_quat, mocap_quat_mut, mocap_quat, f64, |m: &ffi::mjModel| 4 * m.nmocap as usize;
        /// Geom positions `[ngeom * 3]`.
        geom_xpos, geom_xpos_mut, geom_xpos, f64, |m: &ffi::mjModel| 3 * m.ngeom as usize;
        /// Geom orientations, row-major 3×3 `[ngeom * 9]`.
        geom_xmat, geom_xmat_mut, geom_xmat, f64, |m: &ffi::mjModel| 9 * m.ngeom as usize;
    }

    /// World position of body `id`.
    pub fn body_pos(&self, id: usize) -> [f64; 3] {
        let p = &self.xpos()[3 * id..3 * id + 3];
        [p[0], p[1], p[2]]
    }

    /// World orientation of body `id`, quaternion (w, x, y, z).
    pub fn body_quat(&self, id: usize) -> [f64; 4] {
        let q = &self.xquat()[4 * id..4 * id + 4];
        [q[0], q[1], q[2], q[3]]
    }

    /// World position of site `id`.
    pub fn site_pos(&self, id: usize) -> [f64; 3] {
        let p = &self.site_xpos()[3 * id..3 * id + 3];
        [p[0], p[1], p[2]]
    }

    /// World orientation of site `id`, row-major 3×3.
    pub fn site_mat(&self, id: usize) -> [f64; 9] {
        let mut r = [0.0; 9];
        r.copy_from_slice(&self.site_xmat()[9 * id..9 * id + 9]);
        r
    }

    /// World position of geom `id`.
    pub fn geom_pos(&self, id: usize) -> [f64; 3] {
        let p = &self.geom_xpos()[3 * id..3 * id + 3];
        [p[0], p[1], p[2]]
    }

    /// World orientation of geom `id`, row-major 3×3.
    pub fn geom_mat(&self, id: usize) -> [f64; 9] {
        let mut r = [0.0; 9];
        r.copy_from_slice(&self.geom_xmat()[9 * id..9 * id + 9]);
        r
    }

    /// Active contacts after the last forward/step.
    pub fn contacts(&self) -> Vec<Contact> {
        let n = self.raw().ncon.max(0) as usize;
        // SAFETY: `ncon` entries of `contact` are valid after collision detection.
        let raw = unsafe { std::slice::from_raw_parts(self.raw().contact, n) };
        raw.iter()
            .map(|c| Contact {
                geom1: c.geom1 as usize,
                geom2: c.geom2 as usize,
                dist: c.dist,
                pos: c.pos,
                normal: [c.frame[0], c.frame[1], c.frame[2]],
            })
            .collect()
    }

    /// Site Jacobian: translational and rotational parts, each `[3 * nv]` row-major.
    pub fn jac_site(&mut self, site: usize) -> (Vec<f64>, Vec<f64>) {
        assert!(site < self.model.nsite(), "site id out of range");
        let nv = self.model.nv();
        let (mut jp, mut jr) = (vec![0.0; 3 * nv], vec![0.0; 3 * nv]);
        let (m, d) = (self.model.ptr(), self.raw.as_ptr());
        // SAFETY: buffers hold 3*nv entries each; site index checked.
        unsafe { ffi::mj_jacSite(m, d, jp.as_mut_ptr(), jr.as_mut_ptr(), site as c_int) };
        (jp, jr)
    }

    /// Site Jacobian into caller buffers, each `[3 * nv]` row-major (no allocation).
    pub fn jac_site_into(&mut self, site: usize, jacp: &mut [f64], jacr: &mut [f64]) {
        let nv = self.model.nv();
        assert!(site < self.model.nsite(), "site id out of range");
        assert!(
            jacp.len() == 3 * nv && jacr.len() == 3 * nv,
            "Jacobian buffers must be [3 * nv]"
        );
        let (m, d) = (self.model.ptr(), self.raw.as_ptr());
        // SAFETY: buffer sizes checked.
        unsafe { ffi::mj_jacSite(m, d, jacp.as_mut_ptr(), jacr.as_mut_ptr(), site as c_int) };
    }

    /// Body Jacobian (at the body frame origin): translational and rotational, each `[3 * nv]`.
    pub fn jac_body(&mut self, body: usize) -> (Vec<f64>, Vec<f64>) {
        assert!(body < self.model.nbody(), "body id out of range");
        let nv = self.model.nv();
        let (mut jp, mut jr) = (vec![0.0; 3 * nv], vec![0.0; 3 * nv]);
        let (m, d) = (self.model.ptr(), self.raw.as_ptr());
        // SAFETY: buffers hold 3*nv entries each.
        unsafe { ffi::mj_jacBody(m, d, jp.as_mut_ptr(), jr.as_mut_ptr(), body as c_int) };
        (jp, jr)
    }

    /// Dense joint-space mass matrix `[nv * nv]`, row-major (`mj_fullM`).
    pub fn mass_matrix(&self) -> Vec<f64> {
        let nv = self.model.nv();
        let mut out = vec![0.0; nv * nv];
        self.mass_matrix_into(&mut out);
        out
    }

    /// Dense mass matrix into a caller buffer `[nv * nv]`.
    pub fn mass_matrix_into(&self, out: &mut [f64]) {
        let nv = self.model.nv();
        assert!(out.len() == nv * nv, "mass matrix buffer must be [nv * nv]");
        // SAFETY: qM is valid after a forward pass; out has nv*nv entries.
        unsafe { ffi::mj_fullM(self.model.ptr(), out.as_mut_ptr(), self.raw().qM) };
    }

    /// Casts a ray from `pnt` along `vec` (need not be unit length); returns the distance in units of
    /// `|vec|` and the geom hit, or `None`. Geom groups are all included; `exclude_body` (-1: none) is skipped.
    pub fn ray(&self, pnt: [f64; 3], vec: [f64; 3], exclude_body: i32) -> Option<(f64, usize)> {
        let mut geomid: c_int = -1;
        // SAFETY: valid pointers; geomgroup NULL = all groups.
        let dist = unsafe {
            ffi::mj_ray(
                self.model.ptr(),
                self.raw.as_ptr(),
                pnt.as_ptr(),
                vec.as_ptr(),
                std::ptr::null(),
                1,
                exclude_body,
                &mut geomid,
            )
        };
        (geomid >= 0 && dist >= 0.0).then_some((dist, geomid as usize))
    }
}

impl Clone for Data {
    /// Deep copy of the state (`mj_copyData`).
    fn clone(&self) -> Data {
        let m = self.model.ptr();
        // SAFETY: mj_copyData with a NULL destination allocates a new mjData.
        let raw = unsafe { ffi::mj_copyData(std::ptr::null_mut(), m, self.raw.as_ptr()) };
        Data {
            model: Arc::clone(&self.model),
            raw: NonNull::new(raw).expect("mj_copyData failed to allocate"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PENDULUM: &str = r#"
<mujoco>
  <compiler autolimits="true"/>
  <option timestep="0.002"/>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="hinge" type="hinge" axis="0 1 0"/>
      <geom name="rod" type="capsule" fromto="0 0 0 0.5 0 0" size="0.02" mass="1"/>
      <site name="tip" pos="0.5 0 0"/>
    </body>
  </worldbody>
  <actuator><motor name="m" joint="hinge" ctrlrange="-1 1"/></actuator>
</mujoco>"#;

    #[test]
    fn version_is_222() {
        init().unwrap();
        assert_eq!(version(), 222);
    }

    #[test]
    fn loads_from_string_and_steps() {
        let model = Arc::new(Model::from_xml_str(PENDULUM).unwrap());
        assert_eq!((model.nq(), model.nv(), model.nu()), (1, 1, 1));
        assert_eq!(model.id(ObjType::Joint, "hinge"), Some(0));
        assert_eq!(model.name(ObjType::Site, 0), Some("tip"));
        assert!(model.require(ObjType::Body, "nope").is_err());
        let mut d = Data::new(model.clone()).unwrap();
        d.forward().unwrap();
        assert!((d.site_pos(0)[0] - 0.5).abs() < 1e-12);
        for _ in 0..100 {
            d.step().unwrap();
        }
        assert!((d.time() - 0.2).abs() < 1e-9);
        // Gravity swings the horizontal pendulum down: the hinge angle grows (positive about +y).
        assert!(d.qpos()[0] > 0.05, "qpos {}", d.qpos()[0]);
        let (jp, jr) = d.jac_site(0);
        assert_eq!((jp.len(), jr.len()), (3, 3));
        assert!((jr[1] - 1.0).abs() < 1e-12);
        let mm = d.mass_matrix();
        // Rod of mass 1 and length 0.5 about its end: m l^2 / 3 plus the capsule ends.
        assert!(mm[0] > 0.08 && mm[0] < 0.1, "inertia {}", mm[0]);
    }

    #[test]
    fn malformed_xml_is_an_error_with_mujocos_message() {
        let err = Model::from_xml_str("<mujoco><worldbody><body></mujoco>")
            .err()
            .unwrap();
        let text = err.to_string();
        assert!(text.contains("in-memory MJCF"), "{text}");
        assert!(text.to_lowercase().contains("xml"), "{text}");
        let err =
            Model::from_xml_str("<mujoco><worldbody><geom type='sphere'/></worldbody></mujoco>")
                .err()
                .unwrap();
        assert!(err.to_string().contains("size"), "{err}");
        let err = Model::from_xml_file("/nonexistent/model.xml")
            .err()
            .unwrap();
        assert!(err.to_string().contains("/nonexistent/model.xml"), "{err}");
    }

    #[test]
    fn engine_error_becomes_err_and_process_survives() {
        init().unwrap();
        // mju_error through the public API: an out-of-range id check inside MuJoCo.
        let r = guard(|| {
            let msg = CString::new("synthetic failure").unwrap();
            // SAFETY: mju_error takes a NUL-terminated message and calls our hook.
            unsafe { ffi::mju_error(msg.as_ptr()) }
        });
        match r {
            Err(MjError::Engine(m)) => assert!(m.contains("synthetic failure"), "{m}"),
            other => panic!("expected an engine error, got {other:?}"),
        }
        // The process is still alive and MuJoCo still works.
        let model = Model::from_xml_str(PENDULUM).unwrap();
        assert_eq!(model.nq(), 1);
    }

    #[test]
    fn warnings_are_collected_not_logged() {
        init().unwrap();
        let msg = CString::new("synthetic warning").unwrap();
        // SAFETY: NUL-terminated message.
        unsafe { ffi::mju_warning(msg.as_ptr()) };
        assert!(
            take_warnings()
                .iter()
                .any(|w| w.contains("synthetic warning"))
        );
        assert!(!Path::new("MUJOCO_LOG.TXT").exists());
    }

    #[test]
    fn ray_hits_the_rod() {
        let model = Arc::new(Model::from_xml_str(PENDULUM).unwrap());
        let mut d = Data::new(model).unwrap();
        d.forward().unwrap();
        let (dist, geom) = d.ray([0.25, 0.0, 2.0], [0.0, 0.0, -1.0], -1).unwrap();
        assert_eq!(geom, 0);
        assert!((dist - (1.0 - 0.02)).abs() < 1e-9, "{dist}");
    }

    #[test]
    fn clone_copies_state() {
        let model = Arc::new(Model::from_xml_str(PENDULUM).unwrap());
        let mut d = Data::new(model).unwrap();
        d.qpos_mut()[0] = 0.3;
        let c = d.clone();
        d.qpos_mut()[0] = 0.0;
        assert_eq!(c.qpos()[0], 0.3);
    }
}
