//! Collision bits. Movable objects touch everything; a fixture's frame and its moving parts (drawers,
//! knobs) touch objects and the robot but not each other (a fixture's frame is welded to the world, where
//! MuJoCo's parent filter does not apply).

/// Movable objects: `contype`.
pub const OBJECT_TYPE: u32 = 1;
/// Movable objects: `conaffinity` (objects, arm, fixture frames, fixture parts).
pub const OBJECT_AFFINITY: u32 = 1 | 2 | 4 | 8;
/// Fixture frames: `contype`.
pub const FRAME_TYPE: u32 = 4;
/// Fixture moving parts: `contype`.
pub const PART_TYPE: u32 = 8;
/// Fixture frames and parts: `conaffinity` (objects, pads and tables; arm links).
pub const FIXTURE_AFFINITY: u32 = 1 | 2;
