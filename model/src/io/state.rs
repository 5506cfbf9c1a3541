//! The object-state observation (state mode; MIKASA-Robo's oracle-state mode): per frame one
//! token per object — category, position, orientation, grasp — in an order shuffled once per
//! episode and without instance ids, then padding up to the model's object count, then one
//! token for the robot. An object's identity across time is only known through memory (token
//! k is the same object for a whole episode, as a tracked slot is).
//!
//! Token features ([`FEATURES`] numbers):
//! - object: position ×10 (decimetres, world frame), position − gripper position ×10, the first
//!   two columns of its rotation matrix (the continuous 6-D rotation representation: where an
//!   object's rim or handle lies is linear in them, and not in a quaternion), grasped (0/1), 0, 0;
//! - articulated part (with [`StateSpec::parts`]: a drawer's handle, a stove's knob, one token
//!   each after its object's, category `<object category>/<part>`): the same numbers for the point
//!   the part is taken by and its body's orientation, its object's grasp flag, then the joint
//!   position (a drawer's opening in m, a knob's turn in rad), 0;
//! - robot: gripper position ×10, three zeros, the first two columns of the gripper's rotation
//!   matrix, 0, then the two finger joint positions ×10 (zeros when the spec leaves the fingers
//!   out, [`StateSpec::fingers`]);
//! - padding: zeros;
//! - then, when the spec asks for relative scales s_1…s_m (cm), 3·m more numbers per token:
//!   tanh((object position − gripper position) / s_j) per axis for objects, zeros for the robot
//!   and padding. Linear in centimetres near the gripper and saturating beyond a few s_j, they
//!   give the last centimetres of a reach the resolution that decimetres standardised over the
//!   whole table do not (measured on T9, see `configs/state/t9.toml`);
//! - then, when the spec asks for neighbour scales n_1…n_m (cm), 3·m more numbers per token:
//!   tanh((nearest other object's position − this token's position) / n_j) per axis (nearest in
//!   3-D among the other objects, not their parts; all ones when there is none), zeros for the
//!   robot and padding. Whether a plate holds a bowl, or a basket the cheese, is then a
//!   property of the token itself instead of a comparison between tokens (T7's empty plate).
//! - then, with [`StateSpec::distances`], 2 more numbers per token: the object's distance to the
//!   gripper ×10 and the distance to its nearest other object ×10 (10 when there is none), zeros
//!   for the robot and padding. The offsets above are signed per axis, so "the nearer of two
//!   bowls" or "a plate with nothing on it" is a norm of them, which one attention layer's
//!   linear keys cannot take; a distance is one number such a key can rank tokens by.
//!
//! The numbers are then standardised with the training data's mean and standard deviation per
//! feature, one set for object tokens and one for the robot token ([`StateStats`]): raw, the
//! table height (9 dm) and the resting quaternions are large constants next to the centimetres
//! that matter, and a model fed raw numbers does not learn to use them (measured: T1 stuck at the
//! label-conditioned mean action).
//!
//! Category ids: [`PAD`], [`UNKNOWN`], [`ROBOT`], then the spec's categories in order.

use data::ObjectAnnotation;
use serde::{Deserialize, Serialize};

use crate::error::{ModelError, Result};

/// Numbers per token without relative scales ([`StateSpec::features`] with them).
pub const FEATURES: usize = 15;
/// Category of a padding token.
pub const PAD: i64 = 0;
/// Category of an object whose category the model was not trained with.
pub const UNKNOWN: i64 = 1;
/// Category of the robot token.
pub const ROBOT: i64 = 2;
/// Positions are fed in decimetres (the workspace spans a few of them).
const SCALE: f32 = 10.0;

/// An object's category: its instance name without the trailing instance number
/// (`akita_black_bowl_1` → `akita_black_bowl`).
pub fn category(name: &str) -> &str {
    match name.rsplit_once('_') {
        Some((stem, n)) if !stem.is_empty() && n.chars().all(|c| c.is_ascii_digit()) => stem,
        _ => name,
    }
}

/// What a state-mode model was built for (saved in `processor.json`).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StateSpec {
    /// Object categories, sorted (ids 3, 4, …).
    pub categories: Vec<String>,
    /// Object tokens per frame (scenes with fewer objects are padded).
    pub max_objects: usize,
    /// Scales (cm) of the squashed object − gripper features (none: [`FEATURES`] per token).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub relative_cm: Vec<f32>,
    /// Scales (cm) of the squashed offsets to each token's nearest other object (none: no such
    /// features).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub neighbour_cm: Vec<f32>,
    /// Whether each object token ends with its distances to the gripper and to its nearest other
    /// object (false: no such features).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub distances: bool,
    /// Whether the robot token carries the finger joint positions (false: zeros there). The
    /// fingers tell the gripper command of every frame but the one that starts a close, so a
    /// policy can learn to copy them and then never starts a close on its own.
    #[serde(default = "yes", skip_serializing_if = "is_yes")]
    pub fingers: bool,
    /// Whether each articulated part of an object (episode schema 3) is a token of its own:
    /// without them a drawer's opening and a knob's turn are not observed at all, and a handle's
    /// place is a fixed offset from the cabinet's origin that the model has to learn to rotate.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub parts: bool,
    /// Mean and standard deviation of each feature of object tokens.
    pub object_norm: [Vec<f32>; 2],
    /// Mean and standard deviation of each feature of the robot token.
    pub robot_norm: [Vec<f32>; 2],
}

fn yes() -> bool {
    true
}

fn is_yes(v: &bool) -> bool {
    *v
}

/// Running sums for the standardisation of [`StateSpec`], over frames of the training data.
#[derive(Clone, Debug)]
pub struct StateStats {
    names: Vec<String>,
    max_objects: usize,
    relative_cm: Vec<f32>,
    neighbour_cm: Vec<f32>,
    distances: bool,
    fingers: bool,
    parts: bool,
    /// Count, sum and sum of squares per feature.
    objects: [Vec<f64>; 3],
    robot: [Vec<f64>; 3],
}

impl Default for StateStats {
    fn default() -> Self {
        StateStats::new(&[])
    }
}

/// Numbers per token with the squashed relative features at `relative_cm`, the neighbour
/// features at `neighbour_cm` and, with `distances`, the two distances.
fn features_with(relative_cm: &[f32], neighbour_cm: &[f32], distances: bool) -> usize {
    FEATURES + 3 * relative_cm.len() + 3 * neighbour_cm.len() + 2 * usize::from(distances)
}

/// The first of `relative_cm` that is not a usable scale (finite and > 0 cm), if any.
pub fn bad_relative_scale(relative_cm: &[f32]) -> Option<f32> {
    relative_cm
        .iter()
        .copied()
        .find(|s| !(s.is_finite() && *s > 0.0))
}

/// Smallest standard deviation used (features that hardly vary are only centred).
const MIN_STD: f64 = 0.1;

impl StateStats {
    /// Statistics of tokens with the squashed relative features at `relative_cm` (none: the
    /// [`FEATURES`] base numbers only, as [`Default`]).
    pub fn new(relative_cm: &[f32]) -> Self {
        let zeros = || std::array::from_fn(|_| vec![0.0; features_with(relative_cm, &[], false)]);
        StateStats {
            names: Vec::new(),
            max_objects: 0,
            relative_cm: relative_cm.to_vec(),
            neighbour_cm: Vec::new(),
            distances: false,
            fingers: true,
            parts: false,
            objects: zeros(),
            robot: zeros(),
        }
    }

    /// The same statistics for tokens whose robot token leaves out the finger joint positions
    /// ([`StateSpec::fingers`] false).
    pub fn without_fingers(mut self) -> Self {
        self.fingers = false;
        self
    }

    /// The same statistics for tokens with the squashed offsets to the nearest other object at
    /// `neighbour_cm` ([`StateSpec::neighbour_cm`]); call before adding frames.
    pub fn with_neighbours(mut self, neighbour_cm: &[f32]) -> Self {
        self.neighbour_cm = neighbour_cm.to_vec();
        self.resize();
        self
    }

    /// The same statistics for tokens that end with the two distances
    /// ([`StateSpec::distances`]); call before adding frames.
    pub fn with_distances(mut self, distances: bool) -> Self {
        self.distances = distances;
        self.resize();
        self
    }

    /// Sizes the sums to the features the options ask for.
    fn resize(&mut self) {
        let nf = features_with(&self.relative_cm, &self.neighbour_cm, self.distances);
        for acc in [&mut self.objects, &mut self.robot] {
            for v in acc.iter_mut() {
                v.resize(nf, 0.0);
            }
        }
    }

    /// The same statistics for tokens that include every articulated part of an object
    /// ([`StateSpec::parts`]).
    pub fn with_parts(mut self) -> Self {
        self.parts = true;
        self
    }

    /// Adds one frame: the objects in scene order (with poses) and the robot's proprio state.
    pub fn add(&mut self, objects: &[ObjectAnnotation], state: &[f32; 8]) -> Result<()> {
        let sources = sources(self.parts, objects);
        for s in &sources {
            if !self.names.iter().any(|n| *n == s.name) {
                self.names.push(s.name.to_string());
            }
        }
        self.max_objects = self.max_objects.max(sources.len());
        let order: Vec<usize> = (0..sources.len()).collect();
        let spec = StateSpec {
            relative_cm: self.relative_cm.clone(),
            neighbour_cm: self.neighbour_cm.clone(),
            distances: self.distances,
            fingers: self.fingers,
            parts: self.parts,
            ..StateSpec::from_names(sources.iter().map(|s| s.name.as_ref()), sources.len())
        };
        let t = raw_tokens(&spec, objects, state, "0", &order)?;
        let n = sources.len() + 1;
        let nf = spec.features();
        for k in 0..n {
            let acc = if k + 1 == n {
                &mut self.robot
            } else {
                &mut self.objects
            };
            let f = &t.features[k * nf..(k + 1) * nf];
            for d in 0..nf {
                let x = f64::from(f[d]);
                acc[0][d] += 1.0;
                acc[1][d] += x;
                acc[2][d] += x * x;
            }
        }
        Ok(())
    }

    /// Adds the sums of `other` (in a fixed order, so the result does not depend on threads).
    /// Both must have been made with the same relative scales.
    pub fn merge(&mut self, other: &StateStats) {
        assert_eq!(
            self.relative_cm, other.relative_cm,
            "statistics of tokens with different relative scales"
        );
        assert_eq!(
            self.neighbour_cm, other.neighbour_cm,
            "statistics of tokens with different neighbour scales"
        );
        assert_eq!(
            self.distances, other.distances,
            "statistics of tokens with and without distances"
        );
        assert_eq!(
            self.fingers, other.fingers,
            "statistics of tokens with and without fingers"
        );
        assert_eq!(
            self.parts, other.parts,
            "statistics of tokens with and without parts"
        );
        for n in &other.names {
            if !self.names.contains(n) {
                self.names.push(n.clone());
            }
        }
        self.max_objects = self.max_objects.max(other.max_objects);
        for (a, b) in [
            (&mut self.objects, &other.objects),
            (&mut self.robot, &other.robot),
        ] {
            for i in 0..3 {
                for (x, y) in a[i].iter_mut().zip(&b[i]) {
                    *x += y;
                }
            }
        }
    }

    /// The spec of everything added.
    pub fn finish(&self) -> StateSpec {
        let norm = |acc: &[Vec<f64>; 3]| {
            let (means, stds) = (0..acc[0].len())
                .map(|d| {
                    let n = acc[0][d].max(1.0);
                    let mean = acc[1][d] / n;
                    let var = (acc[2][d] / n - mean * mean).max(0.0);
                    (mean as f32, var.sqrt().max(MIN_STD) as f32)
                })
                .unzip();
            [means, stds]
        };
        StateSpec {
            relative_cm: self.relative_cm.clone(),
            neighbour_cm: self.neighbour_cm.clone(),
            distances: self.distances,
            fingers: self.fingers,
            parts: self.parts,
            object_norm: norm(&self.objects),
            robot_norm: norm(&self.robot),
            ..StateSpec::from_names(self.names.iter().map(String::as_str), self.max_objects)
        }
    }
}

impl StateSpec {
    /// The spec of scenes holding the given object instances (names, any number of scenes),
    /// without standardisation (mean 0, standard deviation 1).
    pub fn from_names<'a>(names: impl IntoIterator<Item = &'a str>, max_objects: usize) -> Self {
        let mut categories: Vec<String> = names.into_iter().map(|n| category(n).into()).collect();
        categories.sort();
        categories.dedup();
        StateSpec {
            categories,
            max_objects,
            relative_cm: Vec::new(),
            neighbour_cm: Vec::new(),
            distances: false,
            fingers: true,
            parts: false,
            object_norm: [vec![0.0; FEATURES], vec![1.0; FEATURES]],
            robot_norm: [vec![0.0; FEATURES], vec![1.0; FEATURES]],
        }
    }

    /// Numbers per token F: [`FEATURES`], then 3 per relative scale, then 3 per neighbour scale,
    /// then 2 with [`StateSpec::distances`].
    pub fn features(&self) -> usize {
        features_with(&self.relative_cm, &self.neighbour_cm, self.distances)
    }

    /// Checks that the standardisation has one mean and deviation per feature and that the
    /// relative scales are positive (a hand-edited or corrupt `processor.json`).
    pub fn validate(&self) -> Result<()> {
        let nf = self.features();
        for (what, cm) in [
            ("relative", &self.relative_cm),
            ("neighbour", &self.neighbour_cm),
        ] {
            if let Some(s) = bad_relative_scale(cm) {
                return Err(ModelError::Config(format!(
                    "state {what} scale {s} cm: scales are finite and > 0"
                )));
            }
        }
        for (what, norm) in [
            ("object_norm", &self.object_norm),
            ("robot_norm", &self.robot_norm),
        ] {
            if norm.iter().any(|v| v.len() != nf)
                || norm[1]
                    .iter()
                    .any(|s| s.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater))
            {
                return Err(ModelError::Config(format!(
                    "state {what}: expected {nf} means and {nf} deviations > 0, one per feature"
                )));
            }
        }
        Ok(())
    }

    /// Object tokens of a frame with `objects` (each object, and each of its parts with
    /// [`StateSpec::parts`]): the length of the episode's [`order`].
    pub fn object_tokens(&self, objects: &[ObjectAnnotation]) -> usize {
        objects.len()
            + if self.parts {
                objects.iter().map(|o| o.parts.len()).sum()
            } else {
                0
            }
    }

    /// Tokens per frame N (objects and the robot).
    pub fn tokens(&self) -> usize {
        self.max_objects + 1
    }

    /// Category ids C (padding, unknown and robot included).
    pub fn num_categories(&self) -> usize {
        self.categories.len() + 3
    }

    /// The id of an instance's category.
    pub fn category_id(&self, name: &str) -> i64 {
        self.categories
            .binary_search_by(|c| c.as_str().cmp(category(name)))
            .map_or(UNKNOWN, |i| i as i64 + 3)
    }
}

/// The order in which an episode's `n` objects are given: a permutation drawn from the episode
/// seed (splitmix64 + Fisher–Yates, written out so that train and eval agree for ever), the
/// same for every frame of the episode. `order[k]` is the object at token k.
pub fn order(seed: u64, n: usize) -> Vec<usize> {
    let mut z = seed ^ 0x5747_e0b1_ec75_0a7e;
    let mut next = || {
        z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut x = z;
        x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        x ^ (x >> 31)
    };
    let mut p: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = (next() % (i as u64 + 1)) as usize;
        p.swap(i, j);
    }
    p
}

/// The token that object `object` (an index into `objects`, scene order) is given at under
/// `order` (see [`order`]): its own token, not one of its parts'. None when out of range.
pub fn object_token(
    spec: &StateSpec,
    objects: &[ObjectAnnotation],
    order: &[usize],
    object: usize,
) -> Option<usize> {
    if object >= objects.len() {
        return None;
    }
    let source = if spec.parts {
        objects[..object].iter().map(|o| 1 + o.parts.len()).sum()
    } else {
        object
    };
    order.iter().position(|&i| i == source)
}

/// Rotation matrix (row-major) of a unit quaternion (w, x, y, z).
fn quat_matrix([w, x, y, z]: [f32; 4]) -> [[f32; 3]; 3] {
    let n = (w * w + x * x + y * y + z * z).sqrt().max(1e-12);
    let (w, x, y, z) = (w / n, x / n, y / n, z / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// Rotation matrix of an axis-angle vector (Rodrigues).
fn axis_angle_matrix(v: [f32; 3]) -> [[f32; 3]; 3] {
    let angle = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if angle < 1e-9 {
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    let (s, c) = (angle / 2.0).sin_cos();
    let k = s / angle;
    quat_matrix([c, v[0] * k, v[1] * k, v[2] * k])
}

/// The first two columns of a rotation matrix, column by column.
fn rotation_columns(m: [[f32; 3]; 3]) -> [f32; 6] {
    [m[0][0], m[1][0], m[2][0], m[0][1], m[1][1], m[2][1]]
}

/// The tokens of one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct StateTokens {
    /// Features `[N, F]` (F = [`StateSpec::features`]).
    pub features: Vec<f32>,
    /// Category ids `[N]`.
    pub categories: Vec<i64>,
    /// Oracle labels `[N]`: each object's latest subgoal label, the robot's latest satisfied
    /// subgoal, `"0"` for padding.
    pub labels: Vec<String>,
}

/// The tokens of one frame: `objects` in scene order (with poses), the robot's proprio `state`
/// (eef position, axis-angle, finger qpos), the robot's label, and the episode's `order`;
/// standardised with the spec's statistics.
pub fn tokens(
    spec: &StateSpec,
    objects: &[ObjectAnnotation],
    state: &[f32; 8],
    robot_label: &str,
    order: &[usize],
) -> Result<StateTokens> {
    let mut t = raw_tokens(spec, objects, state, robot_label, order)?;
    let n = spec.tokens();
    let nf = spec.features();
    for k in 0..n {
        let [mean, std] = if k + 1 == n {
            &spec.robot_norm
        } else if t.categories[k] == PAD {
            continue;
        } else {
            &spec.object_norm
        };
        for (d, x) in t.features[k * nf..(k + 1) * nf].iter_mut().enumerate() {
            *x = (*x - mean[d]) / std[d];
        }
    }
    Ok(t)
}

/// What one object token is made of: an object, or one of its articulated parts.
struct Source<'a> {
    /// The name whose [`category`] is the token's: the object's, or `<object category>/<part>`.
    name: std::borrow::Cow<'a, str>,
    /// The object the token is or belongs to.
    object: &'a ObjectAnnotation,
    /// The pose fed (a part's grasp point and orientation), None when the object has none.
    pose: Option<[f32; 7]>,
    /// A part's joint position (0 for an object).
    joint: f32,
}

/// The object tokens of a frame in scene order: every object, each followed by its parts when
/// `parts`.
fn sources(parts: bool, objects: &[ObjectAnnotation]) -> Vec<Source<'_>> {
    let mut out = Vec::with_capacity(objects.len());
    for o in objects {
        out.push(Source {
            name: o.name.as_str().into(),
            object: o,
            pose: o.pose,
            joint: 0.0,
        });
        if parts {
            for p in &o.parts {
                out.push(Source {
                    name: format!("{}/{}", category(&o.name), p.name).into(),
                    object: o,
                    pose: Some(p.pose),
                    joint: p.joint,
                });
            }
        }
    }
    out
}

/// The position of the object nearest (3-D) to `at` among `objects` other than `own` (compared
/// by address: a token's own object and, for a part, the object it belongs to), if any has a
/// pose.
fn nearest_other(
    objects: &[ObjectAnnotation],
    own: &ObjectAnnotation,
    at: [f32; 3],
) -> Option<[f32; 3]> {
    objects
        .iter()
        .filter(|o| !std::ptr::eq(*o, own))
        .filter_map(|o| o.pose.map(|p| [p[0], p[1], p[2]]))
        .map(|p| {
            let d2: f32 = (0..3).map(|d| (p[d] - at[d]) * (p[d] - at[d])).sum();
            (d2, p)
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, p)| p)
}

/// [`tokens`] before standardisation.
fn raw_tokens(
    spec: &StateSpec,
    objects: &[ObjectAnnotation],
    state: &[f32; 8],
    robot_label: &str,
    order: &[usize],
) -> Result<StateTokens> {
    let sources = sources(spec.parts, objects);
    if sources.len() > spec.max_objects {
        return Err(ModelError::Input(format!(
            "{} objects{} in the scene, the model reads at most {}",
            sources.len(),
            if spec.parts { " and parts" } else { "" },
            spec.max_objects
        )));
    }
    if order.len() != sources.len() {
        return Err(ModelError::Input(format!(
            "an order of {} objects for {} objects",
            order.len(),
            sources.len()
        )));
    }
    let n = spec.tokens();
    let nf = spec.features();
    let mut features = vec![0.0f32; n * nf];
    let mut categories = vec![PAD; n];
    let mut labels = vec!["0".to_string(); n];
    let eef = [state[0], state[1], state[2]];
    for (k, &i) in order.iter().enumerate() {
        let s = &sources[i];
        let o = s.object;
        let pose = s.pose.ok_or_else(|| {
            ModelError::Input(format!(
                "object `{}` has no pose (the data was recorded without object poses)",
                o.name
            ))
        })?;
        let f = &mut features[k * nf..(k + 1) * nf];
        for d in 0..3 {
            f[d] = pose[d] * SCALE;
            f[3 + d] = (pose[d] - eef[d]) * SCALE;
            for (j, s) in spec.relative_cm.iter().enumerate() {
                f[FEATURES + 3 * j + d] = ((pose[d] - eef[d]) * 100.0 / s).tanh();
            }
        }
        f[6..12].copy_from_slice(&rotation_columns(quat_matrix([
            pose[3], pose[4], pose[5], pose[6],
        ])));
        let near = (!spec.neighbour_cm.is_empty() || spec.distances)
            .then(|| nearest_other(objects, o, [pose[0], pose[1], pose[2]]))
            .flatten();
        if spec.distances {
            let at = FEATURES + 3 * (spec.relative_cm.len() + spec.neighbour_cm.len());
            let dist = |a: [f32; 3]| (0..3).map(|d| (a[d] - pose[d]).powi(2)).sum::<f32>().sqrt();
            f[at] = dist(eef) * SCALE;
            f[at + 1] = near.map_or(10.0, |p| dist(p) * SCALE);
        }
        if !spec.neighbour_cm.is_empty() {
            let at = FEATURES + 3 * spec.relative_cm.len();
            for (j, s) in spec.neighbour_cm.iter().enumerate() {
                for d in 0..3 {
                    f[at + 3 * j + d] = near.map_or(1.0, |p| ((p[d] - pose[d]) * 100.0 / s).tanh());
                }
            }
        }
        f[12] = f32::from(u8::from(o.grasped.unwrap_or(false)));
        f[13] = s.joint;
        categories[k] = spec.category_id(&s.name);
        labels[k] = o.subgoal_label.clone();
    }
    let r = &mut features[(n - 1) * nf..];
    for d in 0..3 {
        r[d] = eef[d] * SCALE;
    }
    r[6..12].copy_from_slice(&rotation_columns(axis_angle_matrix([
        state[3], state[4], state[5],
    ])));
    if spec.fingers {
        r[13] = state[6] * SCALE;
        r[14] = state[7] * SCALE;
    }
    categories[n - 1] = ROBOT;
    labels[n - 1] = robot_label.to_string();
    Ok(StateTokens {
        features,
        categories,
        labels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obj(name: &str, x: f32, label: &str) -> ObjectAnnotation {
        ObjectAnnotation {
            instance_id: 7,
            name: name.into(),
            bbox: [0.0; 4],
            visible: true,
            subgoal_label: label.into(),
            pose: Some([x, 0.1, 0.9, 1.0, 0.0, 0.0, 0.0]),
            grasped: Some(x > 0.0),
            parts: Vec::new(),
        }
    }

    #[test]
    fn categories_drop_instance_numbers() {
        assert_eq!(category("akita_black_bowl_1"), "akita_black_bowl");
        assert_eq!(category("plate_12"), "plate");
        assert_eq!(category("basket"), "basket");
        assert_eq!(category("_3"), "_3");
        let spec = StateSpec::from_names(["plate_1", "plate_2", "bowl_1"], 4);
        assert_eq!(spec.categories, ["bowl", "plate"]);
        assert_eq!(spec.category_id("plate_3"), 4);
        assert_eq!(spec.category_id("mug_1"), UNKNOWN);
        assert_eq!((spec.tokens(), spec.num_categories()), (5, 5));
    }

    #[test]
    fn order_is_a_permutation_that_differs_across_seeds() {
        let orders: Vec<Vec<usize>> = (0..20).map(|s| order(s, 6)).collect();
        for o in &orders {
            let mut s = o.clone();
            s.sort();
            assert_eq!(s, (0..6).collect::<Vec<_>>());
        }
        assert_eq!(order(3, 6), orders[3], "same seed, same order");
        let distinct: std::collections::BTreeSet<_> = orders.iter().collect();
        assert!(
            distinct.len() >= 15,
            "{} distinct orders of 20",
            distinct.len()
        );
        assert!(order(0, 0).is_empty());
    }

    #[test]
    fn tokens_follow_the_order_and_carry_no_instance_id() {
        let spec = StateSpec::from_names(["bowl_1", "plate_1"], 3);
        let objects = [
            obj("bowl_1", 0.2, "one: bowl 1 on plate 1"),
            obj("plate_1", -0.1, "0"),
        ];
        let state = [0.1, 0.1, 1.0, 0.5, 0.0, 0.0, 0.02, -0.02];
        let t = tokens(&spec, &objects, &state, "one: bowl 1 on plate 1", &[1, 0]).unwrap();
        assert_eq!(t.categories, vec![4, 3, PAD, ROBOT]);
        assert_eq!(
            t.labels,
            ["0", "one: bowl 1 on plate 1", "0", "one: bowl 1 on plate 1"]
        );
        let f = |k: usize| &t.features[k * FEATURES..(k + 1) * FEATURES];
        // Token 0 is the plate: x −0.1 m → −1 dm, relative x −2 dm, not grasped.
        assert!((f(0)[0] + 1.0).abs() < 1e-6 && (f(0)[3] + 2.0).abs() < 1e-6);
        assert_eq!(f(0)[12], 0.0);
        assert_eq!(f(1)[12], 1.0);
        // The identity quaternion: columns (1, 0, 0) and (0, 1, 0).
        assert_eq!(&f(0)[6..12], &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        assert!(f(2).iter().all(|&v| v == 0.0), "padding");
        // The robot: axis-angle 0.5 rad about x → second column (0, cos 0.5, sin 0.5).
        assert!((f(3)[0] - 1.0).abs() < 1e-6 && (f(3)[13] - 0.2).abs() < 1e-6);
        assert!((f(3)[10] - 0.5f32.cos()).abs() < 1e-5 && (f(3)[11] - 0.5f32.sin()).abs() < 1e-5);
        // Nothing in a token depends on the instance id.
        let mut renumbered = objects.clone();
        renumbered.iter_mut().for_each(|o| o.instance_id = 99);
        let u = tokens(
            &spec,
            &renumbered,
            &state,
            "one: bowl 1 on plate 1",
            &[1, 0],
        )
        .unwrap();
        assert_eq!(u, t);
    }

    #[test]
    fn statistics_standardise_object_and_robot_tokens() {
        let mut stats = StateStats::default();
        let state = |x: f32| [x, 0.0, 1.0, 0.0, 0.0, 0.0, 0.02, -0.02];
        let mut a = StateStats::default();
        a.add(&[obj("bowl_1", 0.1, "0")], &state(0.0)).unwrap();
        let mut b = StateStats::default();
        b.add(
            &[obj("bowl_1", 0.3, "0"), obj("plate_1", 0.3, "0")],
            &state(0.2),
        )
        .unwrap();
        stats.merge(&a);
        stats.merge(&b);
        let spec = stats.finish();
        assert_eq!(spec.categories, ["bowl", "plate"]);
        assert_eq!(spec.max_objects, 2);
        // Object x in dm: 1, 3, 3 → mean 7/3; the robot x: 0, 2 → mean 1, std 1.
        let [mean, std] = spec.object_norm.clone();
        assert!((mean[0] - 7.0 / 3.0).abs() < 1e-5, "{mean:?}");
        assert!((std[0] - (8.0f32 / 9.0).sqrt()).abs() < 1e-5, "{std:?}");
        assert_eq!(std[7], MIN_STD as f32, "a constant is only centred");
        assert_eq!((spec.robot_norm[0][0], spec.robot_norm[1][0]), (1.0, 1.0));
        // Standardised tokens: the object's x is (3 − 7/3) / std, padding stays zero.
        let t = tokens(&spec, &[obj("plate_1", 0.3, "0")], &state(0.2), "0", &[0]).unwrap();
        assert!((t.features[0] - (2.0 / 3.0) / std[0]).abs() < 1e-5);
        assert!(t.features[FEATURES..2 * FEATURES].iter().all(|&v| v == 0.0));
        assert!(
            (t.features[2 * FEATURES] - 1.0).abs() < 1e-5,
            "robot x (2 − 1) / 1"
        );
    }

    #[test]
    fn relative_scales_add_squashed_offsets_and_old_specs_still_load() {
        let mut stats = StateStats::new(&[1.0, 10.0]);
        let state = [0.1, 0.1, 1.0, 0.0, 0.0, 0.0, 0.02, -0.02];
        stats
            .add(
                &[obj("bowl_1", 0.12, "0"), obj("plate_1", -0.1, "0")],
                &state,
            )
            .unwrap();
        let spec = stats.finish();
        assert_eq!(spec.features(), FEATURES + 6);
        assert_eq!(spec.object_norm[0].len(), FEATURES + 6);
        spec.validate().unwrap();
        let raw = StateSpec {
            object_norm: [vec![0.0; FEATURES + 6], vec![1.0; FEATURES + 6]],
            robot_norm: [vec![0.0; FEATURES + 6], vec![1.0; FEATURES + 6]],
            ..spec.clone()
        };
        let t = tokens(&raw, &[obj("bowl_1", 0.12, "0")], &state, "0", &[0]).unwrap();
        let nf = FEATURES + 6;
        let f = &t.features[..nf];
        // Δx = 2 cm: tanh(2 / 1) at 1 cm and tanh(2 / 10) at 10 cm; Δy = 0; Δz = −10 cm.
        assert!((f[FEATURES] - 2.0f32.tanh()).abs() < 1e-5, "{f:?}");
        assert!((f[FEATURES + 3] - 0.2f32.tanh()).abs() < 1e-5, "{f:?}");
        assert!(f[FEATURES + 1].abs() < 1e-5 && f[FEATURES + 4].abs() < 1e-5);
        assert!((f[FEATURES + 5] - (-1.0f32).tanh()).abs() < 1e-4, "{f:?}");
        // Padding (token 1) and the robot (token 2) carry zeros there.
        assert!(t.features[2 * nf - 6..2 * nf].iter().all(|&v| v == 0.0));
        assert!(t.features[3 * nf - 6..3 * nf].iter().all(|&v| v == 0.0));
        assert_eq!(t.features.len(), 3 * nf);
        // A spec saved before relative scales existed reads as none.
        let mut json: serde_json::Value =
            serde_json::to_value(StateSpec::from_names(["bowl_1"], 1)).unwrap();
        assert!(json.get("relative_cm").is_none(), "not written when empty");
        json["object_norm"] =
            serde_json::to_value([[0.0f32; FEATURES], [1.0f32; FEATURES]]).unwrap();
        let old: StateSpec = serde_json::from_value(json).unwrap();
        assert_eq!(old.features(), FEATURES);
        old.validate().unwrap();
        // A spec whose standardisation does not match its features is refused.
        let bad = StateSpec {
            relative_cm: vec![2.0],
            ..old
        };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("expected 18 means"), "{e}");
    }

    /// `spec` validated, with mean 0 and deviation 1 for every feature (raw numbers out).
    fn unstandardised(spec: &StateSpec) -> StateSpec {
        spec.validate().unwrap();
        let nf = spec.features();
        StateSpec {
            object_norm: [vec![0.0; nf], vec![1.0; nf]],
            robot_norm: [vec![0.0; nf], vec![1.0; nf]],
            ..spec.clone()
        }
    }

    #[test]
    fn neighbour_scales_give_the_offset_to_the_nearest_other_object() {
        let state = [0.0, 0.0, 1.2, 0.0, 0.0, 0.0, 0.0, 0.0];
        // A plate holding a bowl 3 cm above it, and an empty plate 30 cm away.
        let mut bowl = obj("bowl_1", 0.0, "0");
        bowl.pose = Some([0.0, 0.1, 0.93, 1.0, 0.0, 0.0, 0.0]);
        let full = obj("plate_1", 0.0, "0");
        let empty = obj("plate_2", -0.3, "0");
        let objects = [full, bowl, empty];
        let mut stats = StateStats::new(&[2.0]).with_neighbours(&[3.0, 10.0]);
        stats.add(&objects, &state).unwrap();
        let spec = stats.finish();
        assert_eq!(spec.neighbour_cm, [3.0, 10.0]);
        assert_eq!(spec.features(), FEATURES + 3 + 6);
        assert_eq!(spec.object_norm[0].len(), FEATURES + 9);
        let (nf, raw) = (spec.features(), unstandardised(&spec));
        let t = tokens(&raw, &objects, &state, "0", &[0, 1, 2]).unwrap();
        let at = FEATURES + 3;
        let f = |k: usize| &t.features[k * nf + at..(k + 1) * nf];
        // The full plate's nearest object is its bowl: (0, 0, +3 cm).
        let t3 = 1.0f32.tanh();
        assert!(f(0)[0].abs() < 1e-5 && f(0)[1].abs() < 1e-5, "{:?}", f(0));
        assert!((f(0)[2] - t3).abs() < 1e-4 && (f(0)[5] - 0.3f32.tanh()).abs() < 1e-4);
        // The bowl's is the plate below it: (0, 0, −3 cm).
        assert!((f(1)[2] + t3).abs() < 1e-4, "{:?}", f(1));
        // The empty plate's is the full plate 30 cm away in x: saturated at 3 cm.
        assert!((f(2)[0] - 10.0f32.tanh()).abs() < 1e-5 && (f(2)[3] - 3.0f32.tanh()).abs() < 1e-5);
        // The robot token carries zeros there; the features follow the scene, not the order.
        assert!(t.features[3 * nf + at..4 * nf].iter().all(|&v| v == 0.0));
        let u = tokens(&raw, &objects, &state, "0", &[2, 0, 1]).unwrap();
        assert_eq!(&u.features[at..nf], f(2));
        // A lone object has no neighbour: all ones.
        let lone = tokens(&raw, &objects[..1], &state, "0", &[0]).unwrap();
        assert!(lone.features[at..nf].iter().all(|&v| v == 1.0));
        // A scale that is not a number of cm > 0 is refused.
        let bad = StateSpec {
            neighbour_cm: vec![0.0, 10.0],
            ..spec
        };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("state neighbour scale 0 cm"), "{e}");
    }

    #[test]
    fn distances_rank_objects_by_gripper_and_neighbour_distance() {
        // The gripper 10 cm above the full plate's bowl; the empty plate 30 cm away in x.
        let state = [0.0, 0.1, 1.03, 0.0, 0.0, 0.0, 0.0, 0.0];
        let mut bowl = obj("bowl_1", 0.0, "0");
        bowl.pose = Some([0.0, 0.1, 0.93, 1.0, 0.0, 0.0, 0.0]);
        let objects = [obj("plate_1", 0.0, "0"), bowl, obj("plate_2", -0.3, "0")];
        let mut stats = StateStats::new(&[2.0])
            .with_neighbours(&[3.0])
            .with_distances(true);
        stats.add(&objects, &state).unwrap();
        let spec = stats.finish();
        assert!(spec.distances);
        assert_eq!(spec.features(), FEATURES + 3 + 3 + 2);
        assert_eq!(spec.object_norm[0].len(), spec.features());
        let (nf, raw) = (spec.features(), unstandardised(&spec));
        let t = tokens(&raw, &objects, &state, "0", &[0, 1, 2]).unwrap();
        let d = |k: usize| [t.features[k * nf + nf - 2], t.features[k * nf + nf - 1]];
        let near = |a: f32, b: f32| (a - b).abs() < 1e-4;
        // Full plate: 13 cm below the gripper, its bowl 3 cm above it (×10: decimetres).
        assert!(near(d(0)[0], 1.3) && near(d(0)[1], 0.3), "{:?}", d(0));
        // Bowl: 10 cm below the gripper, the plate 3 cm below it.
        assert!(near(d(1)[0], 1.0) && near(d(1)[1], 0.3), "{:?}", d(1));
        // Empty plate: √(30² + 13²) cm from the gripper, 30 cm from the full plate.
        let g = (0.3f32 * 0.3 + 0.13 * 0.13).sqrt() * 10.0;
        assert!(near(d(2)[0], g) && near(d(2)[1], 3.0), "{:?}", d(2));
        // The robot token carries zeros there; a lone object's neighbour distance is 10 (1 m).
        assert_eq!(d(3), [0.0, 0.0]);
        let lone = tokens(&raw, &objects[..1], &state, "0", &[0]).unwrap();
        assert_eq!(lone.features[nf - 1], 10.0);
        // Old specs (no such field) read as without distances.
        let mut json = serde_json::to_value(&spec).unwrap();
        json.as_object_mut().unwrap().remove("distances");
        let old: StateSpec = serde_json::from_value(json).unwrap();
        assert!(!old.distances);
        assert!(old.validate().is_err(), "norms sized for the distances");
    }

    #[test]
    fn fingers_can_be_left_out_of_the_robot_token() {
        let state = [0.1, 0.1, 1.0, 0.0, 0.0, 0.0, 0.02, -0.03];
        let objects = [obj("bowl_1", 0.12, "0")];
        let (mut with, mut without) = (
            StateStats::default(),
            StateStats::default().without_fingers(),
        );
        with.add(&objects, &state).unwrap();
        without.add(&objects, &state).unwrap();
        let (a, b) = (with.finish(), without.finish());
        assert!(a.fingers && !b.fingers);
        // Finger x 10: 0.2 and −0.3 with them, zeros (only centred) without.
        assert!((a.robot_norm[0][13] - 0.2).abs() < 1e-6);
        assert!((a.robot_norm[0][14] + 0.3).abs() < 1e-6);
        assert_eq!((b.robot_norm[0][13], b.robot_norm[0][14]), (0.0, 0.0));
        let (ta, tb) = (
            tokens(&a, &objects, &state, "0", &[0]).unwrap(),
            tokens(&b, &objects, &state, "0", &[0]).unwrap(),
        );
        let mut other = state;
        other[6] = 0.0;
        other[7] = 0.0;
        assert_eq!(
            tokens(&b, &objects, &other, "0", &[0]).unwrap(),
            tb,
            "without fingers, the finger joints change nothing"
        );
        assert_ne!(tokens(&a, &objects, &other, "0", &[0]).unwrap(), ta);
        // Everything else is the same; specs saved before the option read as with fingers.
        assert_eq!(
            ta.features[..2 * FEATURES - 2],
            tb.features[..2 * FEATURES - 2]
        );
        let json = serde_json::to_value(&a).unwrap();
        assert!(json.get("fingers").is_none(), "not written when true");
        assert_eq!(serde_json::to_value(&b).unwrap()["fingers"], false);
        assert_eq!(serde_json::from_value::<StateSpec>(json).unwrap(), a);
    }

    #[test]
    fn articulated_parts_are_tokens_of_their_own_with_the_joint_position() {
        let mut cabinet = obj("wooden_cabinet_1", 0.3, "one: open drawer");
        cabinet.parts = ["top_handle", "middle_handle"]
            .iter()
            .enumerate()
            .map(|(i, name)| data::PartState {
                name: (*name).into(),
                pose: [0.3, -0.1, 1.0 - 0.07 * i as f32, 1.0, 0.0, 0.0, 0.0],
                joint: -0.05 * i as f32,
            })
            .collect();
        let objects = [obj("bowl_1", 0.2, "0"), cabinet];
        let state = [0.1, 0.1, 1.0, 0.0, 0.0, 0.0, 0.02, -0.02];
        let mut stats = StateStats::default().with_parts();
        stats.add(&objects, &state).unwrap();
        let spec = stats.finish();
        assert!(spec.parts);
        assert_eq!(
            spec.categories,
            [
                "bowl",
                "wooden_cabinet",
                "wooden_cabinet/middle_handle",
                "wooden_cabinet/top_handle"
            ]
        );
        assert_eq!((spec.max_objects, spec.object_tokens(&objects)), (4, 4));
        let raw = StateSpec {
            object_norm: [vec![0.0; FEATURES], vec![1.0; FEATURES]],
            robot_norm: [vec![0.0; FEATURES], vec![1.0; FEATURES]],
            ..spec.clone()
        };
        // Scene order: bowl, cabinet, its top handle, its middle handle; fed reversed.
        let t = tokens(&raw, &objects, &state, "0", &[3, 2, 1, 0]).unwrap();
        assert_eq!(t.categories, vec![5, 6, 4, 3, ROBOT]);
        // The pointer's target token of an object is its own, not one of its parts'.
        let token = |o| object_token(&raw, &objects, &[3, 2, 1, 0], o);
        assert_eq!((token(0), token(1), token(2)), (Some(3), Some(2), None));
        let flat = StateSpec {
            parts: false,
            ..raw.clone()
        };
        assert_eq!(object_token(&flat, &objects, &[1, 0], 0), Some(1));
        assert_eq!(
            t.labels[..3],
            ["one: open drawer"; 3],
            "a part has its object's label"
        );
        let f = |k: usize| &t.features[k * FEATURES..(k + 1) * FEATURES];
        // The middle handle: z 0.93 m → 9.3 dm, joint −0.05 in feature 13, the cabinet's grasp.
        assert!((f(0)[2] - 9.3).abs() < 1e-5 && (f(0)[13] + 0.05).abs() < 1e-7);
        assert_eq!((f(0)[12], f(2)[13], f(3)[13]), (1.0, 0.0, 0.0));
        // Without parts the same scene is two object tokens, and the spec does not say parts.
        let plain = StateSpec {
            parts: false,
            ..raw.clone()
        };
        assert_eq!(plain.object_tokens(&objects), 2);
        let u = tokens(&plain, &objects, &state, "0", &[1, 0]).unwrap();
        assert_eq!(u.categories, vec![4, 3, PAD, PAD, ROBOT]);
        assert!(serde_json::to_value(&plain).unwrap().get("parts").is_none());
        assert_eq!(serde_json::to_value(&raw).unwrap()["parts"], true);
        let e = tokens(&raw, &objects, &state, "0", &[1, 0]).unwrap_err();
        assert!(e.to_string().contains("an order of 2 objects for 4"), "{e}");
    }

    #[test]
    fn missing_poses_and_crowded_scenes_are_errors() {
        let spec = StateSpec::from_names(["bowl_1"], 1);
        let mut o = obj("bowl_1", 0.0, "0");
        o.pose = None;
        let e = tokens(&spec, &[o], &[0.0; 8], "0", &[0]).unwrap_err();
        assert!(e.to_string().contains("no pose"), "{e}");
        let e = tokens(
            &spec,
            &[obj("bowl_1", 0.0, "0"), obj("bowl_2", 0.0, "0")],
            &[0.0; 8],
            "0",
            &[0, 1],
        )
        .unwrap_err();
        assert!(e.to_string().contains("at most 1"), "{e}");
    }
}
