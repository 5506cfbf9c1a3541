//! Exponential moving average of the weights (`[train] ema`): a copy of the model, without
//! autodiff, that follows the trained weights after every optimiser step,
//! `ema ← decay · ema + (1 − decay) · weights`. Burn has no weight average of its own; the two
//! models are walked side by side in module order (the same structure, so the same order).

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::prelude::*;

/// Collects every float parameter's value, without autodiff and flattened, in module order.
struct Collect(Vec<Tensor<1>>);

impl ModuleVisitor for Collect {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let v = param.val().without_autodiff();
        let n = v.shape().num_elements();
        self.0.push(v.reshape([n]));
    }
}

/// Moves each averaged parameter towards the collected value of the same position.
struct Blend {
    live: std::vec::IntoIter<Tensor<1>>,
    decay: f64,
    mismatch: Option<String>,
}

impl ModuleMapper for Blend {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let Some(live) = self.live.next() else {
            self.mismatch
                .get_or_insert_with(|| "the average has more parameters".into());
            return param;
        };
        let decay = self.decay;
        let mismatch = &mut self.mismatch;
        param.map(|e| {
            let dims = e.dims();
            if live.shape().num_elements() != e.shape().num_elements() {
                mismatch.get_or_insert_with(|| format!("a parameter of shape {dims:?} differs"));
                return e;
            }
            // e + (1 − decay)(w − e): one multiply-add per element.
            let w = live.reshape(dims);
            e.clone() + (w - e).mul_scalar(1.0 - decay)
        })
    }
}

/// The average's starting point: `model`'s weights, without autodiff.
pub fn start<M: Module>(model: &M) -> M {
    model.valid()
}

/// One averaging step: `ema ← decay · ema + (1 − decay) · live`, parameter by parameter.
/// `ema` and `live` are the same architecture; a structural mismatch is an error.
pub fn update<M: Module>(ema: M, live: &M, decay: f64) -> Result<M, String> {
    let mut c = Collect(vec![]);
    live.visit(&mut c);
    let mut b = Blend {
        live: c.0.into_iter(),
        decay,
        mismatch: None,
    };
    let out = ema.map(&mut b);
    if b.live.next().is_some() {
        b.mismatch
            .get_or_insert_with(|| "the trained model has more parameters".into());
    }
    match b.mismatch {
        Some(m) => Err(format!("weight average: {m}")),
        None => Ok(out),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::nn::{Linear, LinearConfig};

    fn values(m: &Linear) -> Vec<f32> {
        let mut v = m.weight.val().into_data().try_to_vec::<f32>().unwrap();
        v.extend(
            m.bias
                .as_ref()
                .unwrap()
                .val()
                .into_data()
                .try_to_vec::<f32>()
                .unwrap(),
        );
        v
    }

    #[test]
    fn follows_the_weights_by_the_decay() {
        let device = Device::flex().autodiff();
        device.seed(5);
        let a = LinearConfig::new(3, 2).init(&device);
        let b = a.clone().map(&mut Scale(2.0)).fork(&device);
        let ema = start(&a);
        assert!(!ema.weight.val().is_autodiff());
        assert_eq!(values(&ema), values(&a));
        // One step with decay 0.75 towards b = 2a: 0.75 a + 0.25 · 2a = 1.25 a.
        let ema = update(ema, &b, 0.75).unwrap();
        for (e, x) in values(&ema).iter().zip(values(&a)) {
            assert!(
                (e - 1.25 * x).abs() <= 1e-6 * x.abs().max(1.0),
                "{e} vs {x}"
            );
        }
        // Parameter ids stay the average's own.
        assert_eq!(ema.weight.id, a.weight.id);
        // Another architecture is an error, not a panic.
        let other = LinearConfig::new(2, 2).init(&device);
        let err = update(ema, &other, 0.5).unwrap_err();
        assert!(err.contains("differs"), "{err}");
    }

    /// Multiplies every float parameter by a constant.
    struct Scale(f64);
    impl ModuleMapper for Scale {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let k = self.0;
            param.map(|t| t.mul_scalar(k))
        }
    }
}
