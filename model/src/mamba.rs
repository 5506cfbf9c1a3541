//! Mamba (S6) selective SSM mixer with a parallel scan for training and a step form for
//! inference (model.md §4).
//!
//! Every sequence in the batch has its own state; in SlotSSM the batch is (B·K), so weights are
//! shared across slots while states stay separate (a block-diagonal transition).

use burn::module::Param;
use burn::nn::{Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::Distribution;
use burn::tensor::activation::{relu, silu};

use crate::config::SsmConfig;

/// Recurrent state of one Mamba mixer.
#[derive(Clone, Debug)]
pub struct MambaState {
    /// SSM state h `[N, E, S]`.
    pub h: Tensor<3>,
    /// The last d_conv − 1 conv inputs, oldest first, `[N, E, d_conv − 1]`.
    pub conv: Tensor<3>,
}

impl MambaState {
    /// Zero state for `n` sequences.
    pub fn zeros(n: usize, inner: usize, state: usize, conv: usize, device: &Device) -> Self {
        MambaState {
            h: Tensor::zeros([n, inner, state], device),
            conv: Tensor::zeros([n, inner, conv - 1], device),
        }
    }

    /// Detaches both tensors from the autodiff graph.
    pub fn detach(self) -> Self {
        MambaState {
            h: self.h.detach(),
            conv: self.conv.detach(),
        }
    }

    /// Number of floats held.
    pub fn num_floats(&self) -> usize {
        self.h.shape().num_elements() + self.conv.shape().num_elements()
    }
}

/// The S6 mixer.
#[derive(Module, Debug)]
pub struct Mamba {
    /// [x ‖ z] = W_in u, `[D, 2E]`, no bias.
    pub in_proj: Linear,
    /// Depthwise causal conv kernel `[E, d_conv]` (tap j multiplies x_{t−d_conv+1+j}).
    pub conv_weight: Param<Tensor<2>>,
    /// Conv bias `[E]`.
    pub conv_bias: Param<Tensor<1>>,
    /// [δ ‖ B ‖ C] = W_x x̃, `[E, dt_rank + 2S]`, no bias.
    pub x_proj: Linear,
    /// Δ = softplus(W_dt δ + b_dt), `[dt_rank, E]` with bias.
    pub dt_proj: Linear,
    /// A = −exp(A_log), `[E, S]`.
    pub a_log: Param<Tensor<2>>,
    /// Skip D `[E]`.
    pub d_skip: Param<Tensor<1>>,
    /// Output `[E, D]`, no bias.
    pub out_proj: Linear,
    /// E.
    pub inner: usize,
    /// S.
    pub state: usize,
    /// d_conv.
    pub conv: usize,
    /// dt_rank.
    pub dt_rank: usize,
}

impl Mamba {
    /// Builds a mixer of width `d` with Mamba's initialisation (S4D-real A, Δ₀ in [1e-3, 1e-1]).
    pub fn new(d: usize, cfg: &SsmConfig, device: &Device) -> Self {
        let (e, s, r) = (cfg.inner, cfg.state, cfg.dt_rank);
        let a_log: Vec<f32> = (0..e)
            .flat_map(|_| (0..s).map(|n| ((n + 1) as f32).ln()))
            .collect();
        // Δ₀ = exp(U[ln 1e-3, ln 1e-1]) ≥ 1e-4, b_dt = inverse softplus(Δ₀), computed in f64.
        let u: Vec<f32> = Tensor::<1>::random([e], Distribution::Uniform(0.0, 1.0), device)
            .into_data()
            .try_to_vec::<f32>()
            .expect("f32 data");
        let (lo, hi) = (1e-3f64.ln(), 1e-1f64.ln());
        let b_dt: Vec<f32> = u
            .iter()
            .map(|&u| {
                let dt = (lo + (hi - lo) * u as f64).exp().max(1e-4);
                (dt + (-(-dt).exp_m1()).ln()) as f32
            })
            .collect();
        let bound = (r as f64).powf(-0.5);
        let dt_proj = Linear {
            weight: Param::from_tensor(Tensor::random(
                [r, e],
                Distribution::Uniform(-bound, bound),
                device,
            )),
            bias: Some(Param::from_tensor(Tensor::from_data(
                TensorData::new(b_dt, [e]),
                device,
            ))),
        };
        let conv_bound = (cfg.conv as f64).powf(-0.5);
        Mamba {
            in_proj: LinearConfig::new(d, 2 * e).with_bias(false).init(device),
            conv_weight: Param::from_tensor(Tensor::random(
                [e, cfg.conv],
                Distribution::Uniform(-conv_bound, conv_bound),
                device,
            )),
            conv_bias: Param::from_tensor(Tensor::random(
                [e],
                Distribution::Uniform(-conv_bound, conv_bound),
                device,
            )),
            x_proj: LinearConfig::new(e, r + 2 * s)
                .with_bias(false)
                .init(device),
            dt_proj,
            a_log: Param::from_tensor(Tensor::from_data(TensorData::new(a_log, [e, s]), device)),
            d_skip: Param::from_tensor(Tensor::ones([e], device)),
            out_proj: LinearConfig::new(e, d).with_bias(false).init(device),
            inner: e,
            state: s,
            conv: cfg.conv,
            dt_rank: r,
        }
    }

    /// A zero state for `n` sequences.
    pub fn zero_state(&self, n: usize, device: &Device) -> MambaState {
        MambaState::zeros(n, self.inner, self.state, self.conv, device)
    }

    /// Δ, B, C from the convolved input.
    ///
    /// # Shapes
    /// - xc: `[..., E]` → (Δ `[..., E]`, B `[..., S]`, C `[..., S]`)
    fn selective<const D: usize>(&self, xc: Tensor<D>) -> (Tensor<D>, Tensor<D>, Tensor<D>) {
        let (r, s) = (self.dt_rank, self.state);
        let dbc = self.x_proj.forward(xc);
        let delta = dbc.clone().narrow(D - 1, 0, r);
        let b = dbc.clone().narrow(D - 1, r, s);
        let c = dbc.narrow(D - 1, r + s, s);
        let delta = stable_softplus(self.dt_proj.forward(delta));
        (delta, b, c)
    }

    /// A = −exp(A_log), `[E, S]`.
    fn a(&self) -> Tensor<2> {
        self.a_log.val().exp().neg()
    }

    /// Parallel (training) form over a whole sequence, starting from `state` (None = zeros).
    ///
    /// # Shapes
    /// - u: `[N, T, D]`
    /// - output: (y `[N, T, D]`, state after the last step)
    pub fn forward(&self, u: Tensor<3>, state: Option<MambaState>) -> (Tensor<3>, MambaState) {
        let [n, t, _] = u.dims();
        let (e, s, kc) = (self.inner, self.state, self.conv);
        let device = u.device();
        let state = state.unwrap_or_else(|| self.zero_state(n, &device));
        assert_shape!(state.h, [n, e, s]);
        assert_shape!(state.conv, [n, e, kc - 1]);

        let xz = self.in_proj.forward(u);
        let x = xz.clone().narrow(2, 0, e);
        let z = xz.narrow(2, e, e);

        // Causal depthwise conv: prefix the buffered inputs, then sum d_conv shifted slices.
        let padded = Tensor::cat(vec![state.conv.swap_dims(1, 2), x], 1); // [N, T+kc−1, E]
        let w = self.conv_weight.val();
        let mut acc = self.conv_bias.val().reshape([1, 1, e]);
        for j in 0..kc {
            let wj = w.clone().narrow(1, j, 1).reshape([1, 1, e]);
            acc = acc + padded.clone().narrow(1, j, t) * wj;
        }
        let xc = silu(acc); // [N, T, E]
        let new_conv = padded.narrow(1, t, kc - 1).swap_dims(1, 2);

        let (delta, b, c) = self.selective(xc.clone());
        let delta4 = delta.clone().unsqueeze_dim::<4>(3); // [N, T, E, 1]
        let a_bar = (delta4 * self.a().reshape([1, 1, e, s])).exp(); // [N, T, E, S]
        let bx = (delta * xc.clone()).unsqueeze_dim::<4>(3) * b.unsqueeze_dim::<4>(2);
        let h = parallel_scan(a_bar, bx, Some(state.h));
        let y = (h.clone() * c.unsqueeze_dim::<4>(2))
            .sum_dim(3)
            .squeeze_dim::<3>(3)
            + xc * self.d_skip.val().reshape([1, 1, e]);
        let out = self.out_proj.forward(y * silu(z));
        let h_last = h.narrow(1, t - 1, 1).squeeze_dim::<3>(1);
        (
            out,
            MambaState {
                h: h_last,
                conv: new_conv,
            },
        )
    }

    /// Step (inference) form: one token per sequence.
    ///
    /// # Shapes
    /// - u: `[N, D]`
    /// - output: (y `[N, D]`, the next state)
    pub fn step(&self, u: Tensor<2>, state: MambaState) -> (Tensor<2>, MambaState) {
        let [n, _] = u.dims();
        let (e, s, kc) = (self.inner, self.state, self.conv);
        assert_shape!(state.h, [n, e, s]);
        let xz = self.in_proj.forward(u);
        let x = xz.clone().narrow(1, 0, e);
        let z = xz.narrow(1, e, e);
        let window = Tensor::cat(vec![state.conv, x.unsqueeze_dim::<3>(2)], 2); // [N, E, kc]
        let xc = silu(
            (window.clone() * self.conv_weight.val().unsqueeze_dim::<3>(0))
                .sum_dim(2)
                .squeeze_dim::<2>(2)
                + self.conv_bias.val().unsqueeze_dim::<2>(0),
        );
        let conv = window.narrow(2, 1, kc - 1);
        let (delta, b, c) = self.selective(xc.clone());
        let a_bar = (delta.clone().unsqueeze_dim::<3>(2) * self.a().unsqueeze_dim::<3>(0)).exp();
        let bx = (delta * xc.clone()).unsqueeze_dim::<3>(2) * b.unsqueeze_dim::<3>(1);
        let h = a_bar * state.h + bx; // [N, E, S]
        let y = (h.clone() * c.unsqueeze_dim::<3>(1))
            .sum_dim(2)
            .squeeze_dim::<2>(2)
            + xc * self.d_skip.val().unsqueeze_dim::<2>(0);
        let out = self.out_proj.forward(y * silu(z));
        (out, MambaState { h, conv })
    }
}

/// softplus(x) = max(x, 0) + ln(1 + e^{−|x|}), stable for any x.
///
/// # Shapes
/// - x: any → same
pub fn stable_softplus<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    relu(x.clone()) + x.abs().neg().exp().log1p()
}

/// Hillis–Steele inclusive scan of h_t = a_t ⊙ h_{t−1} + b_t along axis 1, with h_{−1} = `h_init`.
///
/// Uses only slice, cat, mul and add: ⌈log₂ T⌉ rounds, no loop over T.
///
/// # Shapes
/// - a, b: `[N, T, E, S]`; h_init: `[N, E, S]`
/// - output: h `[N, T, E, S]`
pub fn parallel_scan(a: Tensor<4>, b: Tensor<4>, h_init: Option<Tensor<3>>) -> Tensor<4> {
    let [n, t, e, s] = a.dims();
    assert_shape!(b, [n, t, e, s]);
    let device = a.device();
    let mut a = a;
    let mut b = b;
    if let Some(h0) = h_init {
        assert_shape!(h0, [n, e, s]);
        // Fold h_init into the first step: b₀ ← a₀ ⊙ h_init + b₀.
        let first =
            a.clone().narrow(1, 0, 1) * h0.unsqueeze_dim::<4>(1) + b.clone().narrow(1, 0, 1);
        b = if t > 1 {
            Tensor::cat(vec![first, b.narrow(1, 1, t - 1)], 1)
        } else {
            first
        };
    }
    // Round d: h_i ← h_i + a_i ⊙ h_{i−d} and a_i ← a_i ⊙ a_{i−d} (a zero / one shift in
    // front: each round is then two slices and two cats, which autodiff's backward handles more
    // cheaply than slicing the tails apart). The last round's products of a are never read.
    let mut d = 1;
    while d < t {
        let last = 2 * d >= t;
        let b_shift = Tensor::cat(
            vec![
                Tensor::zeros([n, d, e, s], &device),
                b.clone().narrow(1, 0, t - d),
            ],
            1,
        );
        if last {
            return b + a * b_shift;
        }
        let a_shift = Tensor::cat(
            vec![
                Tensor::ones([n, d, e, s], &device),
                a.clone().narrow(1, 0, t - d),
            ],
            1,
        );
        b = b + a.clone() * b_shift;
        a = a * a_shift;
        d *= 2;
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_device;

    fn cfg() -> SsmConfig {
        SsmConfig {
            blocks: 1,
            heads: 2,
            inner: 16,
            state: 4,
            conv: 4,
            dt_rank: 2,
            cross_attention: false,
            ffn: false,
        }
    }

    fn max_diff<const D: usize>(a: Tensor<D>, b: Tensor<D>) -> f32 {
        (a - b).abs().max().into_scalar()
    }

    #[test]
    fn scan_matches_sequential_recurrence() {
        let (_guard, device) = test_device();
        device.seed(7);
        for t in [1, 2, 5, 8, 13] {
            let a = Tensor::<4>::random([3, t, 2, 2], Distribution::Uniform(0.0, 1.0), &device);
            let b = Tensor::<4>::random([3, t, 2, 2], Distribution::Normal(0.0, 1.0), &device);
            let h0 = Tensor::<3>::random([3, 2, 2], Distribution::Normal(0.0, 1.0), &device);
            let h = parallel_scan(a.clone(), b.clone(), Some(h0.clone()));
            let mut prev = h0;
            for i in 0..t {
                prev = a.clone().narrow(1, i, 1).squeeze_dim::<3>(1) * prev
                    + b.clone().narrow(1, i, 1).squeeze_dim::<3>(1);
                let got = h.clone().narrow(1, i, 1).squeeze_dim::<3>(1);
                assert!(max_diff(got, prev.clone()) < 1e-5, "T={t} step {i}");
            }
        }
    }

    #[test]
    fn softplus_is_stable() {
        let (_guard, device) = test_device();
        let x = Tensor::<1>::from_floats([-100.0, -1.0, 0.0, 2.0, 100.0], &device);
        let y = stable_softplus(x).into_data().try_to_vec::<f32>().unwrap();
        let want = [
            0.0f32,
            0.313_261_7,
            std::f32::consts::LN_2,
            2.126_928,
            100.0,
        ];
        for (a, b) in y.iter().zip(want) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }

    #[test]
    fn init_follows_mamba() {
        let (_guard, device) = test_device();
        let m = Mamba::new(8, &cfg(), &device);
        let a = m.a().into_data().try_to_vec::<f32>().unwrap();
        assert!((a[0] + 1.0).abs() < 1e-6 && (a[3] + 4.0).abs() < 1e-5);
        // softplus(b_dt) = Δ₀ ∈ [1e-3, 1e-1].
        let dt = stable_softplus(m.dt_proj.bias.as_ref().unwrap().val())
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        assert!(dt.iter().all(|&v| (0.9e-3..=1.1e-1).contains(&v)), "{dt:?}");
    }

    fn parallel_equals_steps(random_init: bool) {
        let (_guard, device) = test_device();
        device.seed(11);
        let m = Mamba::new(8, &cfg(), &device);
        let (n, t) = (3, 9);
        let u = Tensor::<3>::random([n, t, 8], Distribution::Normal(0.0, 1.0), &device);
        let state = if random_init {
            MambaState {
                h: Tensor::random([n, 16, 4], Distribution::Normal(0.0, 1.0), &device),
                conv: Tensor::random([n, 16, 3], Distribution::Normal(0.0, 1.0), &device),
            }
        } else {
            m.zero_state(n, &device)
        };
        let (y, last) = m.forward(u.clone(), Some(state.clone()));
        assert_eq!(y.dims(), [n, t, 8]);
        let mut st = state;
        for i in 0..t {
            let (yi, next) = m.step(u.clone().narrow(1, i, 1).squeeze_dim::<2>(1), st);
            st = next;
            let d = max_diff(yi, y.clone().narrow(1, i, 1).squeeze_dim::<2>(1));
            assert!(d < 1e-5, "step {i}: {d}");
        }
        assert!(max_diff(st.h, last.h) < 1e-5);
        assert!(max_diff(st.conv, last.conv) < 1e-6);
    }

    #[test]
    fn parallel_equals_steps_from_zero_state() {
        parallel_equals_steps(false);
    }

    #[test]
    fn parallel_equals_steps_from_random_state() {
        parallel_equals_steps(true);
    }
}
