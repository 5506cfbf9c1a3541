//! Global-norm gradient clipping (Burn's `GradientClipping::Norm` clips each tensor on its own;
//! the usual recipe clips the norm of all gradients together).

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::prelude::*;

/// Sums ‖g‖² over every float parameter that has a gradient.
struct SquaredNorm<'a> {
    grads: &'a GradientsParams,
    sum: Option<Tensor<1>>,
}

impl ModuleVisitor for SquaredNorm<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(g) = self.grads.get::<D>(param.id) {
            let sq = g.square().sum();
            self.sum = Some(match self.sum.take() {
                Some(s) => s + sq,
                None => sq,
            });
        }
    }
}

/// Multiplies every gradient by a factor.
struct Scale<'a> {
    grads: &'a mut GradientsParams,
    factor: f64,
}

impl ModuleVisitor for Scale<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(g) = self.grads.remove::<D>(param.id) {
            self.grads.register(param.id, g.mul_scalar(self.factor));
        }
    }
}

/// The global L2 norm of `grads` over the parameters of `module`.
pub fn global_norm<M: Module>(module: &M, grads: &GradientsParams) -> f64 {
    let mut v = SquaredNorm { grads, sum: None };
    module.visit(&mut v);
    v.sum
        .map(|s| s.into_scalar::<f32>() as f64)
        .unwrap_or(0.0)
        .sqrt()
}

/// Scales all gradients by `max_norm / norm` when their global norm exceeds `max_norm`
/// (`max_norm` ≤ 0 = off); returns the norm before clipping.
pub fn clip_global_norm<M: Module>(module: &M, grads: &mut GradientsParams, max_norm: f64) -> f64 {
    let norm = global_norm(module, grads);
    if max_norm > 0.0 && norm > max_norm && norm.is_finite() {
        let factor = max_norm / (norm + 1e-6);
        module.visit(&mut Scale { grads, factor });
    }
    norm
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::nn::{Linear, LinearConfig};

    #[derive(Module, Debug)]
    struct Two {
        a: Linear,
        b: Linear,
    }

    #[test]
    fn clips_the_norm_of_all_gradients_together() {
        let device = Device::flex().autodiff();
        device.seed(0);
        let m = Two {
            a: LinearConfig::new(3, 4).init(&device),
            b: LinearConfig::new(4, 2).init(&device),
        };
        let x = Tensor::<2>::ones([5, 3], &device);
        let y = m.b.forward(m.a.forward(x)).sum().mul_scalar(100.0);
        let mut grads = GradientsParams::from_grads(y.backward(), &m);
        let before = global_norm(&m, &grads);
        assert!(before > 1.0);
        let reported = clip_global_norm(&m, &mut grads, 1.0);
        assert_eq!(reported, before);
        let after = global_norm(&m, &grads);
        assert!((after - 1.0).abs() < 1e-3, "{after}");
        // Below the threshold nothing changes.
        assert_eq!(clip_global_norm(&m, &mut grads, 10.0), after);
        assert_eq!(global_norm(&m, &grads), after);
    }
}
