//! What a plan is made of: [`Op`]s that move to live [`Target`]s built from [`Point`]s.

use crate::task::Atom;

/// Where a target point comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Point {
    /// A fixed world point.
    Abs([f64; 3]),
    /// An instance's root body position plus an offset given in the instance's frame (`local`) or in
    /// the world frame.
    Body {
        /// Instance index in [`Scene::instances`](crate::world::scene::Scene::instances).
        inst: usize,
        /// Offset.
        off: [f64; 3],
        /// Whether `off` is expressed in the body frame.
        local: bool,
    },
    /// A bowl's rim on its freer ±y side (decided on the live state, and where given also on the
    /// neighbourhood of the destination the hand will carry it to): the body position plus
    /// `(off.x, ±off.y, off.z)`; `coin` breaks ties.
    Rim {
        /// Instance.
        inst: usize,
        /// Offset (y = rim radius).
        off: [f64; 3],
        /// Tie-break.
        coin: bool,
        /// Where the bowl goes next (the side must be free there too).
        dest: Option<[f64; 3]>,
    },
    /// A site position plus a world offset.
    Site {
        /// Site id.
        site: usize,
        /// World offset.
        off: [f64; 3],
    },
}

/// What a move drives to.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// The grip site to a point.
    Grip(Point),
    /// The held instance's origin to a point (the hand follows with the current hand–object offset).
    Carry {
        /// Held instance.
        held: usize,
        /// Where its origin should go.
        to: Point,
    },
    /// The grip site to its position at the start of the op plus a world offset.
    Rel([f64; 3]),
    /// The grip site to its start position with z replaced.
    RelZ(f64),
    /// From the start position: up by `dz`, and horizontally towards the shoulder until at most `h`
    /// metres from it (far out, a high straight arm is a singularity OSC cannot leave).
    PullIn {
        /// Horizontal distance from the shoulder to get within.
        h: f64,
        /// Lift.
        dz: f64,
    },
}

/// One low-level step of a plan.
#[derive(Debug, Clone, PartialEq)]
pub enum Op {
    /// Proportional move of the grip site to `target` (clipped to [−1, 1]) until within `tol` metres or
    /// `max` steps.
    Move {
        /// Target.
        target: Target,
        /// Gripper command during the move.
        grip: f32,
        /// Tolerance (m).
        tol: f64,
        /// Step limit.
        max: usize,
        /// Proportional gain (action units per metre).
        gain: f64,
        /// Also stop as soon as the pending atom holds (placing).
        until_pending: bool,
    },
    /// Rotate the hand about world z to `yaw` radians from its initial orientation.
    Yaw {
        /// Yaw relative to the initial hand orientation.
        yaw: f64,
        /// Gripper command.
        grip: f32,
        /// Step limit.
        max: usize,
    },
    /// Rotate the hand to `Rtilt · Rz(yaw) · R0` (R0 the initial orientation, Rtilt a rotation by `tilt`
    /// radians about the horizontal axis `axis`), keeping the grip site in place; later moves hold that
    /// orientation while `hold` (until the next `Orient`).
    Orient {
        /// Yaw about world z.
        yaw: f64,
        /// Horizontal tilt axis (world, unit).
        axis: [f64; 3],
        /// Tilt angle.
        tilt: f64,
        /// Gripper command.
        grip: f32,
        /// Step limit.
        max: usize,
        /// Hold the orientation during later moves.
        hold: bool,
    },
    /// Rotate the hand to `rot · R0` (R0 the initial orientation; `rot` row-major), keeping the grip site
    /// in place; later moves hold that orientation while `hold` (until the next rotation op).
    Attitude {
        /// World rotation applied to the initial orientation, row-major.
        rot: [f64; 9],
        /// Gripper command.
        grip: f32,
        /// Step limit.
        max: usize,
        /// Hold the orientation during later moves.
        hold: bool,
    },
    /// Gripper command for a number of steps, arm still.
    Grip {
        /// +1 close, −1 open.
        cmd: f32,
        /// Steps.
        steps: usize,
    },
    /// Stay still for a number of steps.
    Hold {
        /// Steps.
        steps: usize,
        /// Gripper command.
        grip: f32,
    },
    /// Stay still until the goal tracker reports at least `n` satisfied subgoals (or `max` steps).
    WaitSatisfied {
        /// Subgoal count.
        n: usize,
        /// Step limit.
        max: usize,
        /// Gripper command.
        grip: f32,
    },
    /// Skip the next `count` ops when the goal tracker reports at least `n` satisfied subgoals (a
    /// corrective retry that is only needed when a placement was not registered).
    SkipIfSatisfied {
        /// Subgoal count.
        n: usize,
        /// Ops to skip.
        count: usize,
    },
    /// Stay still until the pending atom has been false for `n` steps since the last append.
    WaitNonlive {
        /// Steps.
        n: usize,
        /// Step limit.
        max: usize,
        /// Gripper command.
        grip: f32,
    },
    /// Stay still until `atom` holds (or `max` steps).
    WaitAtom {
        /// The atom.
        atom: Atom,
        /// Step limit.
        max: usize,
        /// Gripper command.
        grip: f32,
    },
    /// Marks the atom the plan now works towards (for [`Op::WaitNonlive`]).
    Pending(Option<Atom>),
}
