//! Staged training (`[[train.stages]]`), as in the reference recipe: first the slot losses with
//! the action side frozen, then the SlotSSM, then the action decoder (or everything). Each stage
//! names the loss terms that form its total (with the config's λ) and the model parts whose
//! weights stay fixed; which stage is active is a function of the step alone, so a resumed run
//! continues in the stage where it stopped.

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::prelude::*;
use model::config::LossConfig;
use model::{Losses, PolicyModel};

use crate::config::Stage;

/// Loss terms a stage may switch on.
pub const LOSSES: [&str; 4] = ["action", "contrastive", "window", "slot_recon"];

/// Model parts a stage may freeze (the fields of [`PolicyModel`]; absent ones are ignored).
pub const MODULES: [&str; 15] = [
    "encoder",
    "slot_attention",
    "slot_ssm",
    "window_head",
    "fusion",
    "null_subgoal",
    "slot_proj",
    "relation",
    "token_proj",
    "patch_proj",
    "token_type",
    "frame_offset",
    "text",
    "decoder",
    "slot_decoder",
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
/// it computes none of them).
pub fn total(stage: &Stage, losses: &Losses, weights: &LossConfig) -> Option<Tensor<1>> {
    let mut total: Option<Tensor<1>> = None;
    for name in &stage.losses {
        let (term, w) = match name.as_str() {
            "action" => (Some(&losses.action), weights.action),
            "contrastive" => (losses.contrastive.as_ref(), weights.contrastive),
            "window" => (losses.window.as_ref(), weights.window),
            "slot_recon" => (losses.slot_recon.as_ref(), weights.slot_recon),
            _ => (None, 0.0),
        };
        if let Some(t) = term {
            let t = t.clone().mul_scalar(w);
            total = Some(match total {
                Some(s) => s + t,
                None => t,
            });
        }
    }
    total
}

/// Drops the gradients of every parameter it visits (the optimiser then leaves them alone:
/// no update, no weight decay, no moment change).
struct DropGrads<'a>(&'a mut GradientsParams);

impl ModuleVisitor for DropGrads<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.0.remove::<D>(param.id);
    }
}

/// Visits the model part `name` (one of [`MODULES`]; nothing for an absent part).
pub fn visit_part<V: ModuleVisitor>(model: &PolicyModel, name: &str, v: &mut V) {
    match name {
        "encoder" => model.encoder.visit(v),
        "slot_attention" => model.slot_attention.visit(v),
        "slot_ssm" => model.slot_ssm.visit(v),
        "window_head" => model.window_head.visit(v),
        "fusion" => model.fusion.visit(v),
        "null_subgoal" => model.null_subgoal.visit(v),
        "slot_proj" => model.slot_proj.visit(v),
        "relation" => model.relation.visit(v),
        "token_proj" => model.token_proj.visit(v),
        "patch_proj" => model.patch_proj.visit(v),
        "token_type" => model.token_type.visit(v),
        "frame_offset" => model.frame_offset.visit(v),
        "text" => model.text.visit(v),
        "decoder" => model.decoder.visit(v),
        "slot_decoder" => model.slot_decoder.visit(v),
        _ => {}
    }
}

/// Removes the gradients of the stage's frozen parts from `grads`.
pub fn freeze(model: &PolicyModel, stage: &Stage, grads: &mut GradientsParams) {
    let mut v = DropGrads(grads);
    for name in &stage.freeze {
        visit_part(model, name, &mut v);
    }
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
        if let Some(m) = s.freeze.iter().find(|m| !MODULES.contains(&m.as_str())) {
            return Err(format!(
                "{at}.freeze: unknown model part `{m}` (expected one of {MODULES:?})"
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
        bad.freeze = vec!["decodr".into()];
        assert!(check(&[bad]).unwrap_err().contains("decodr"));
        let mut bad = stage("x", None);
        bad.losses = vec!["actoin".into()];
        assert!(check(&[bad]).unwrap_err().contains("train.stages[0]"));
    }
}
