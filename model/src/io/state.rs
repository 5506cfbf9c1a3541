//! The object-state observation (state mode; MIKASA-Robo's oracle-state mode): per frame one
//! token per object — category, position, orientation, grasp — in an order shuffled once per
//! episode and without instance ids, then padding up to the model's object count, then one
//! token for the robot. An object's identity across time is only known through memory (token
//! k is the same object for a whole episode, as a tracked slot is).
//!
//! Token features ([`FEATURES`] numbers):
//! - object: position ×10 (decimetres, world frame), position − gripper position ×10, the
//!   quaternion (w, x, y, z), grasped (0/1), 0;
//! - robot: gripper position ×10, three zeros, the gripper axis-angle and 0, then the two
//!   finger joint positions ×10;
//! - padding: zeros.
//!
//! Category ids: [`PAD`], [`UNKNOWN`], [`ROBOT`], then the spec's categories in order.

use data::ObjectAnnotation;
use serde::{Deserialize, Serialize};

use crate::error::{ModelError, Result};

/// Numbers per token.
pub const FEATURES: usize = 12;
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
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
pub struct StateSpec {
    /// Object categories, sorted (ids 3, 4, …).
    pub categories: Vec<String>,
    /// Object tokens per frame (scenes with fewer objects are padded).
    pub max_objects: usize,
}

impl StateSpec {
    /// The spec of scenes holding the given object instances (names, any number of scenes).
    pub fn from_names<'a>(names: impl IntoIterator<Item = &'a str>, max_objects: usize) -> Self {
        let mut categories: Vec<String> = names.into_iter().map(|n| category(n).into()).collect();
        categories.sort();
        categories.dedup();
        StateSpec {
            categories,
            max_objects,
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

/// The tokens of one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct StateTokens {
    /// Features `[N, FEATURES]`.
    pub features: Vec<f32>,
    /// Category ids `[N]`.
    pub categories: Vec<i64>,
    /// Oracle labels `[N]`: each object's latest subgoal label, the robot's latest satisfied
    /// subgoal, `"0"` for padding.
    pub labels: Vec<String>,
}

/// The tokens of one frame: `objects` in scene order (with poses), the robot's proprio `state`
/// (eef position, axis-angle, finger qpos), the robot's label, and the episode's `order`.
pub fn tokens(
    spec: &StateSpec,
    objects: &[ObjectAnnotation],
    state: &[f32; 8],
    robot_label: &str,
    order: &[usize],
) -> Result<StateTokens> {
    if objects.len() > spec.max_objects {
        return Err(ModelError::Input(format!(
            "{} objects in the scene, the model reads at most {}",
            objects.len(),
            spec.max_objects
        )));
    }
    if order.len() != objects.len() {
        return Err(ModelError::Input(format!(
            "an order of {} objects for {} objects",
            order.len(),
            objects.len()
        )));
    }
    let n = spec.tokens();
    let mut features = vec![0.0f32; n * FEATURES];
    let mut categories = vec![PAD; n];
    let mut labels = vec!["0".to_string(); n];
    let eef = [state[0], state[1], state[2]];
    for (k, &i) in order.iter().enumerate() {
        let o = &objects[i];
        let pose = o.pose.ok_or_else(|| {
            ModelError::Input(format!(
                "object `{}` has no pose (the data was recorded without object poses)",
                o.name
            ))
        })?;
        let f = &mut features[k * FEATURES..(k + 1) * FEATURES];
        for d in 0..3 {
            f[d] = pose[d] * SCALE;
            f[3 + d] = (pose[d] - eef[d]) * SCALE;
        }
        f[6..10].copy_from_slice(&pose[3..7]);
        f[10] = f32::from(u8::from(o.grasped.unwrap_or(false)));
        categories[k] = spec.category_id(&o.name);
        labels[k] = o.subgoal_label.clone();
    }
    let r = &mut features[(n - 1) * FEATURES..];
    for d in 0..3 {
        r[d] = eef[d] * SCALE;
        r[6 + d] = state[3 + d];
    }
    r[10] = state[6] * SCALE;
    r[11] = state[7] * SCALE;
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
        assert_eq!(f(0)[10], 0.0);
        assert_eq!(f(1)[10], 1.0);
        assert!(f(2).iter().all(|&v| v == 0.0), "padding");
        assert!((f(3)[0] - 1.0).abs() < 1e-6 && f(3)[6] == 0.5 && (f(3)[10] - 0.2).abs() < 1e-6);
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
