//! Data-parallel replicas within one process: each lane group's gradients come from its own copy
//! of the weights (its loss weighted by its share of the batch's action mass), and Burn's
//! `MultiGradientsParams` sums them per parameter before the global clip and the optimiser step
//! (which need the summed gradient, so the sum is taken here rather than inside
//! `ModuleOptimizer::step_multi`).

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::{GradientsParams, MultiGradientsParams};
use burn::prelude::*;

use crate::metrics::Record;

/// Moves each parameter's summed gradient from `multi` into `out`.
struct Reduce<'a> {
    multi: &'a mut MultiGradientsParams,
    out: &'a mut GradientsParams,
}

impl ModuleVisitor for Reduce<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some((g, _)) = self.multi.remove::<D>(param.id) {
            self.out.register(param.id, g);
        }
    }
}

/// The per-parameter sum of the replicas' gradients (all on `device`), over `module`'s
/// parameters; one replica's gradients are returned as they are.
pub fn sum_gradients<M: Module>(
    module: &M,
    mut grads: Vec<GradientsParams>,
    device: &Device,
) -> GradientsParams {
    if grads.len() == 1 {
        return grads.pop().expect("one element");
    }
    let mut multi = MultiGradientsParams {
        grads: grads.into_iter().map(|g| (g, device.clone())).collect(),
    };
    let mut out = GradientsParams::new();
    module.visit(&mut Reduce {
        multi: &mut multi,
        out: &mut out,
    });
    out
}

/// Each replica's weight in the step's loss: its share of the batch's action mass (the
/// denominator of the masked action loss), so that the weighted sum of the replicas' mean action
/// losses is the whole batch's; equal shares when the batch has no action entries at all.
pub fn replica_weights(masses: &[f64]) -> Vec<f64> {
    let total: f64 = masses.iter().sum();
    if total > 0.0 {
        masses.iter().map(|m| m / total).collect()
    } else {
        vec![1.0 / masses.len().max(1) as f64; masses.len()]
    }
}

/// The replicas' step records, each with its weight, as one: losses weighted as the step's loss
/// was, forward and backward times the slowest replica's (they ran side by side).
pub fn mean_record(mut recs: Vec<(Record, f64)>) -> Record {
    if recs.len() == 1 {
        return recs.remove(0).0;
    }
    let sum = |f: &dyn Fn(&Record) -> f64| recs.iter().map(|(r, w)| w * f(r)).sum::<f64>();
    let opt = |f: &dyn Fn(&Record) -> Option<f64>| {
        recs.iter()
            .map(|(r, w)| f(r).map(|x| w * x))
            .sum::<Option<f64>>()
    };
    let mut out = recs[0].0.clone();
    out.loss = sum(&|r| r.loss);
    out.action = sum(&|r| r.action);
    out.contrastive = opt(&|r| r.contrastive);
    out.window = opt(&|r| r.window);
    out.slot_recon = opt(&|r| r.slot_recon);
    out.pointer = opt(&|r| r.pointer);
    out.progress = opt(&|r| r.progress);
    out.done = opt(&|r| r.done);
    for (r, _) in &recs {
        out.forward_s = out.forward_s.max(r.forward_s);
        out.backward_s = out.backward_s.max(r.backward_s);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::nn::LinearConfig;

    #[test]
    fn sums_each_parameters_gradients_over_replicas() {
        let device = Device::flex().autodiff();
        device.seed(3);
        let m = LinearConfig::new(3, 2).init(&device);
        let grads_of = |x: Vec<f32>| {
            let replica = m.clone().fork(&device);
            let x = Tensor::<1>::from_floats(x.as_slice(), &device).reshape([1, 3]);
            let y = replica.forward(x).sum();
            GradientsParams::from_grads(y.backward(), &replica)
        };
        let a = grads_of(vec![1.0, 2.0, 3.0]);
        let b = grads_of(vec![-4.0, 0.5, 2.0]);
        let whole = grads_of(vec![1.0, 2.0, 3.0]);
        let sum = sum_gradients(&m, vec![a, b], &device);
        // d(sum(xW + b))/dW = xᵀ·1: the sum over the two inputs, (−3, 2.5, 5) in each column.
        let w = sum
            .get::<2>(m.weight.id)
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        assert_eq!(w, vec![-3.0, -3.0, 2.5, 2.5, 5.0, 5.0]);
        let bias = m.bias.as_ref().unwrap().id;
        assert_eq!(
            sum.get::<1>(bias)
                .unwrap()
                .into_data()
                .try_to_vec::<f32>()
                .unwrap(),
            vec![2.0, 2.0]
        );
        // One replica passes through untouched.
        let one = sum_gradients(&m, vec![whole], &device);
        assert_eq!(
            one.get::<2>(m.weight.id)
                .unwrap()
                .into_data()
                .try_to_vec::<f32>()
                .unwrap(),
            vec![1.0, 1.0, 2.0, 2.0, 3.0, 3.0]
        );
    }

    #[test]
    fn records_weigh_losses_and_keep_the_slowest_times() {
        let rec = |loss: f64, win: Option<f64>, fwd: f64| Record {
            loss,
            action: loss / 2.0,
            window: win,
            forward_s: fwd,
            ..Record::default()
        };
        let w = replica_weights(&[30.0, 10.0]);
        assert_eq!(w, vec![0.75, 0.25]);
        let m = mean_record(vec![
            (rec(1.0, Some(0.2), 0.5), w[0]),
            (rec(3.0, Some(0.4), 0.7), w[1]),
        ]);
        assert_eq!(m.loss, 1.5);
        assert_eq!(m.action, 0.75);
        assert!((m.window.unwrap() - 0.25).abs() < 1e-12);
        assert_eq!(m.contrastive, None);
        assert_eq!(m.forward_s, 0.7);
        // No action entries anywhere: equal weights.
        assert_eq!(replica_weights(&[0.0, 0.0]), vec![0.5, 0.5]);
    }
}
