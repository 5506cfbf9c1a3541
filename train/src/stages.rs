//! Staged training (`[[train.stages]]`), as in the reference recipe: first the slot losses with
//! the action side frozen, then the SlotSSM, then the action decoder (or everything). Each stage
//! names the loss terms that form its total (with the config's λ) and the model parts whose
//! weights stay fixed (by module name anywhere in the model tree, found by a `ModuleVisitor`); which stage is active is a function of the step alone, so a resumed run
//! continues in the stage where it stopped.

use std::collections::BTreeSet;

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::prelude::*;
use model::config::LossConfig;
use model::{Losses, PolicyModel};

use serde::{Deserialize, Serialize};

/// `[[train.stages]]`: one stage of staged training. Stages run in order for their `steps`
/// (the last one runs until `[train].steps`); the learning-rate schedule spans the whole run.
///
/// ```toml
/// [[train.stages]]
/// name = "slots"                    # slot attention learns objects first
/// steps = 2000
/// losses = ["slot_recon", "contrastive"]
/// freeze = ["decoder", "slot_ssm"]
/// [[train.stages]]
/// name = "action"                   # then everything, every loss
/// losses = ["action", "contrastive", "window", "slot_recon"]
/// ```
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stage {
    /// Name (metrics and progress bar).
    pub name: String,
    /// Optimiser steps of this stage (may be left out for the last one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steps: Option<u64>,
    /// Loss terms summed (with their λ) into this stage's total: `action`, `contrastive`,
    /// `window`, `slot_recon`, `pointer`, `progress`, `done`.
    pub losses: Vec<String>,
    /// Model parts whose weights stay fixed, by module name anywhere in the model tree
    /// (`encoder`, `slot_attention`, `slot_ssm`, `window_head`, `fusion`, `relation`,
    /// `decoder`, `text`, …; [`parts`] lists a model's).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub freeze: Vec<String>,
    /// Whether the episodes' idle tails (`data.mask_idle_tail`) keep their weight
    /// `data.idle_tail_weight` in this stage's action loss (default true); false leaves them
    /// out, as `data.idle_tail_weight = 0` would (e.g. a first stage that learns the motion before
    /// the tails teach where it stops).
    #[serde(
        default = "crate::config::yes",
        skip_serializing_if = "crate::config::is_yes"
    )]
    pub idle_tail: bool,
}

/// Whether step `step`'s batch weights the idle tails: false only in a stage that says so.
pub fn idle_tail(stages: &[Stage], step: u64) -> bool {
    active(stages, step).is_none_or(|(_, s)| s.idle_tail)
}

/// Loss terms a stage may switch on.
pub const LOSSES: [&str; 7] = [
    "action",
    "contrastive",
    "window",
    "slot_recon",
    "pointer",
    "progress",
    "done",
];

/// The stage of step `step` (steps done so far, 0-based): stages follow each other for their
/// `steps`; the last one runs to the end. `None` without stages.
pub fn active(stages: &[Stage], step: u64) -> Option<(usize, &Stage)> {
    let mut end = 0u64;
    for (i, s) in stages.iter().enumerate() {
        match s.steps {
            Some(n) if i + 1 < stages.len() => {
                end += n;
                if step < end {
                    return Some((i, s));
                }
            }
            _ => return Some((i, s)),
        }
    }
    None
}

/// The stage's total: Σ λ_term · L_term over its `losses` that the model computes (`None` when
/// it computes none of them). Terms of weight 0 are left out of the sum when another term is
/// in it: they add exactly nothing, and the backward pass then skips their graphs (the state
/// configs' contrastive loss is still computed and logged, but no longer differentiated).
pub fn total(stage: &Stage, losses: &Losses, weights: &LossConfig) -> Option<Tensor<1>> {
    let terms: Vec<(&Tensor<1>, f64)> = stage
        .losses
        .iter()
        .filter_map(|name| term(name, losses, weights))
        .collect();
    let weighted = terms.iter().any(|&(_, w)| w != 0.0);
    let mut total: Option<Tensor<1>> = None;
    for (t, w) in terms {
        if weighted && w == 0.0 {
            continue;
        }
        let t = t.clone().mul_scalar(w);
        total = Some(match total {
            Some(s) => s + t,
            None => t,
        });
    }
    total
}

/// The loss named `name` (when the model computes it) and its weight.
fn term<'a>(name: &str, losses: &'a Losses, weights: &LossConfig) -> Option<(&'a Tensor<1>, f64)> {
    let (term, w) = match name {
        "action" => (Some(&losses.action), weights.action),
        "contrastive" => (losses.contrastive.as_ref(), weights.contrastive),
        "window" => (losses.window.as_ref(), weights.window),
        "slot_recon" => (losses.slot_recon.as_ref(), weights.slot_recon),
        "pointer" => (losses.pointer.as_ref(), weights.pointer),
        "progress" => (losses.progress.as_ref(), weights.progress),
        "done" => (losses.done.as_ref(), weights.done),
        _ => (None, 0.0),
    };
    term.map(|t| (t, w))
}

/// Walks the model tree (module path = field and variant names, e.g.
/// `tokens.SlotSsm.core.slot_attention.gru`) and drops the gradients of every parameter that
/// lies inside a module named one of `names`, at any depth (the optimiser then leaves them alone:
/// no update, no weight decay, no moment change). Also collects every name it passes.
struct Freeze<'a> {
    grads: Option<&'a mut GradientsParams>,
    names: &'a [String],
    path: Vec<String>,
    seen: BTreeSet<String>,
}

impl ModuleVisitor for Freeze<'_> {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        // Enum arms (`SlotAttention`) are named as fields are (`slot_attention`).
        let name = snake_case(name);
        self.path.push(name.clone());
        self.seen.insert(name);
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(grads) = self.grads.as_deref_mut()
            && self.path.iter().any(|p| self.names.contains(p))
        {
            grads.remove::<D>(param.id);
        }
    }
}

/// `CamelCase` → `camel_case` (other names unchanged).
pub fn snake_case(name: &str) -> String {
    let mut out = String::with_capacity(name.len() + 4);
    for (i, c) in name.chars().enumerate() {
        if c.is_uppercase() {
            if i > 0 {
                out.push('_');
            }
            out.extend(c.to_lowercase());
        } else {
            out.push(c);
        }
    }
    out
}

/// The names of the model's parts (every module and parameter name in its tree) that a stage
/// may freeze.
pub fn parts(model: &PolicyModel) -> BTreeSet<String> {
    let mut v = Freeze {
        grads: None,
        names: &[],
        path: Vec::new(),
        seen: BTreeSet::new(),
    };
    model.visit(&mut v);
    v.seen
}

/// Removes the gradients of the stage's frozen parts from `grads`.
pub fn freeze(model: &PolicyModel, stage: &Stage, grads: &mut GradientsParams) {
    let mut v = Freeze {
        grads: Some(grads),
        names: &stage.freeze,
        path: Vec::new(),
        seen: BTreeSet::new(),
    };
    model.visit(&mut v);
}

/// Checks that every part a stage freezes exists in `model` (the message names the stage).
pub fn check_freeze(stages: &[Stage], model: &PolicyModel) -> std::result::Result<(), String> {
    let known = parts(model);
    for (i, s) in stages.iter().enumerate() {
        if let Some(m) = s.freeze.iter().find(|m| !known.contains(m.as_str())) {
            let top: Vec<&str> = known
                .iter()
                .map(String::as_str)
                .filter(|n| !n.chars().next().is_some_and(char::is_uppercase))
                .collect();
            return Err(format!(
                "train.stages[{i}] (`{}`).freeze: the `{}` model has no part `{m}` (its parts: {})",
                s.name,
                model.config.variant.name(),
                top.join(", ")
            ));
        }
    }
    Ok(())
}

/// Checks a `[[train.stages]]` list; the message names the key at fault.
pub fn check(stages: &[Stage]) -> std::result::Result<(), String> {
    for (i, s) in stages.iter().enumerate() {
        let at = format!("train.stages[{i}] (`{}`)", s.name);
        if s.steps == Some(0) || (s.steps.is_none() && i + 1 < stages.len()) {
            return Err(format!(
                "{at}.steps: must be ≥ 1 (only the last stage may leave it out: it runs to the end)"
            ));
        }
        if s.losses.is_empty() {
            return Err(format!("{at}.losses: name at least one of {LOSSES:?}"));
        }
        if let Some(l) = s.losses.iter().find(|l| !LOSSES.contains(&l.as_str())) {
            return Err(format!(
                "{at}.losses: unknown term `{l}` (expected one of {LOSSES:?})"
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stage(name: &str, steps: Option<u64>) -> Stage {
        Stage {
            name: name.into(),
            steps,
            losses: vec!["action".into()],
            freeze: vec![],
            idle_tail: true,
        }
    }

    #[test]
    fn stages_follow_each_other_and_the_last_runs_to_the_end() {
        let s = vec![
            stage("a", Some(3)),
            stage("b", Some(2)),
            stage("c", Some(1)),
        ];
        let names: Vec<&str> = (0..9)
            .map(|k| active(&s, k).unwrap().1.name.as_str())
            .collect();
        assert_eq!(names, ["a", "a", "a", "b", "b", "c", "c", "c", "c"]);
        assert!(active(&[], 5).is_none());
        assert!(check(&s).is_ok());
        assert!(check(&[stage("a", None), stage("b", None)]).is_err());
        let mut bad = stage("x", None);
        bad.losses = vec!["actoin".into()];
        assert!(check(&[bad]).unwrap_err().contains("train.stages[0]"));
    }

    #[test]
    fn zero_weight_terms_add_nothing_and_are_not_differentiated() {
        let device = Device::flex().autodiff();
        let x = Tensor::<1>::from_floats([0.5], &device).require_grad();
        let y = Tensor::<1>::from_floats([2.0], &device).require_grad();
        let losses = Losses {
            total: x.clone() + y.clone(),
            action: x.clone().mul_scalar(3.0),
            // NaN (√−1): left out, it cannot poison the total or the gradients.
            contrastive: Some(y.clone().sub_scalar(3.0).sqrt()),
            window: Some(x.clone() * y.clone()),
            slot_recon: None,
            pointer: None,
            progress: None,
            done: None,
        };
        let weights = |contrastive: f64| LossConfig {
            action: 1.0,
            contrastive,
            window: 0.5,
            slot_recon: 0.0,
            gripper: 1.0,
            pointer: 0.0,
            progress: 0.0,
            ..model::ModelConfig::tiny(model::Variant::from_name("e_slotssm").unwrap()).loss
        };
        let mut s = stage("s", None);
        s.losses = ["action", "contrastive", "window", "slot_recon"]
            .map(String::from)
            .into();
        // 3·0.5 + 0.5·(0.5·2) = 2.0; the contrastive term at weight 0 neither counts nor
        // sends a gradient to y beyond the window term's x = 0.5 · 0.5.
        let t = total(&s, &losses, &weights(0.0)).unwrap();
        assert_eq!(t.clone().into_scalar::<f32>(), 2.0);
        let g = t.backward();
        assert_eq!(y.grad(&g).unwrap().into_scalar::<f32>(), 0.25);
        assert_eq!(x.grad(&g).unwrap().into_scalar::<f32>(), 3.0 + 0.5 * 2.0);
        // Weighted, it counts.
        let t = total(&s, &losses, &weights(0.1)).unwrap();
        assert!(t.into_scalar::<f32>().is_nan());
        // A stage of zero-weight terms alone still has a total (0 · L).
        s.losses = vec!["window".into()];
        let mut w = weights(0.0);
        w.window = 0.0;
        assert_eq!(total(&s, &losses, &w).unwrap().into_scalar::<f32>(), 0.0);
        s.losses = vec!["slot_recon".into()];
        assert!(total(&s, &losses, &weights(0.0)).is_none());
    }

    #[test]
    fn idle_tails_are_left_out_only_in_the_stages_that_say_so() {
        assert!((0..10).all(|step| idle_tail(&[], step)));
        let mut first = stage("motion", Some(3));
        first.idle_tail = false;
        let s = vec![first, stage("all", None)];
        let tails: Vec<bool> = (0..6).map(|step| idle_tail(&s, step)).collect();
        assert_eq!(tails, [false, false, false, true, true, true]);
    }

    #[test]
    fn freezing_by_module_name_drops_exactly_those_gradients() {
        use burn::tensor::Distribution;
        let device = Device::flex().autodiff();
        device.seed(0);
        let mut cfg = model::ModelConfig::tiny(model::Variant::from_name("slotvla_h2").unwrap())
            .with_vocab_from(["put the bowl on the plate"]);
        cfg.image_size = [32, 32];
        let m = PolicyModel::new(&cfg, &device).unwrap();
        let known = parts(&m);
        for name in [
            "encoder",
            "slot_attention",
            "relation",
            "decoder",
            "frame_offset",
            "token_type",
        ] {
            assert!(known.contains(name), "{name} in {known:?}");
        }
        let mut frozen = stage("s", None);
        frozen.freeze = vec!["slot_attention".into(), "frame_offset".into()];
        assert!(check_freeze(std::slice::from_ref(&frozen), &m).is_ok());
        let mut typo = stage("s", None);
        typo.freeze = vec!["slot_ssm".into()];
        let e = check_freeze(&[typo], &m).unwrap_err();
        assert!(
            e.contains("`slotvla_h2` model has no part `slot_ssm`"),
            "{e}"
        );

        let images =
            Tensor::<5>::random([1, 2, 3, 32, 32], Distribution::Uniform(0.0, 1.0), &device);
        let ids = model::Tokenizer::new(&cfg.text).encode_batch(&["put the bowl"], &device);
        let out = m.predict(images, ids, None).unwrap();
        let grads = out.actions.sum().backward();
        let mut grads = GradientsParams::from_grads(grads, &m);
        let before = grads.len();
        freeze(&m, &frozen, &mut grads);
        let sa = m
            .tokens
            .slot_core()
            .unwrap()
            .slot_attention()
            .unwrap()
            .num_params();
        assert!(grads.len() < before);
        // Every parameter tensor under slot_attention and the frame offsets is gone, no other.
        struct Count(usize);
        impl ModuleVisitor for Count {
            fn visit_float<const D: usize>(&mut self, _: &Param<Tensor<D>>) {
                self.0 += 1;
            }
        }
        let mut c = Count(0);
        m.tokens
            .slot_core()
            .unwrap()
            .slot_attention()
            .unwrap()
            .visit(&mut c);
        assert_eq!(before - grads.len(), c.0 + 1, "{sa} params");
    }
}
