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

/// The global L2 norm of `grads` over the parameters of `module`; an error when the backend
/// cannot compute it (the device's message).
pub fn global_norm<M: Module>(module: &M, grads: &GradientsParams) -> Result<f64, String> {
    let mut v = SquaredNorm { grads, sum: None };
    module.visit(&mut v);
    match v.sum {
        Some(s) => s
            .try_into_scalar::<f32>()
            .map(|x| (x as f64).sqrt())
            .map_err(|e| e.to_string()),
        None => Ok(0.0),
    }
}

/// Scales all gradients by `max_norm / norm` when their global norm exceeds `max_norm`
/// (`max_norm` ≤ 0 = off); returns the norm before clipping.
pub fn clip_global_norm<M: Module>(
    module: &M,
    grads: &mut GradientsParams,
    max_norm: f64,
) -> Result<f64, String> {
    let norm = global_norm(module, grads)?;
    if max_norm > 0.0 && norm > max_norm && norm.is_finite() {
        let factor = max_norm / (norm + 1e-6);
        module.visit(&mut Scale { grads, factor });
    }
    Ok(norm)
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
        let before = global_norm(&m, &grads).unwrap();
        assert!(before > 1.0);
        let reported = clip_global_norm(&m, &mut grads, 1.0).unwrap();
        assert_eq!(reported, before);
        let after = global_norm(&m, &grads).unwrap();
        assert!((after - 1.0).abs() < 1e-3, "{after}");
        // Below the threshold nothing changes.
        assert_eq!(clip_global_norm(&m, &mut grads, 10.0).unwrap(), after);
        assert_eq!(global_norm(&m, &grads).unwrap(), after);
    }
}
