//! Losses (model.md §2, §3, §5, §8). Each returns a scalar `[1]` tensor; masks are 0/1 floats.

use burn::prelude::*;
use burn::tensor::activation::log_softmax;

use crate::decoder::{NUM_BINS, actions_to_classes};

/// Masked mean: Σ(x·m) / max(Σm, 1).
fn masked_mean<const D: usize>(x: Tensor<D>, mask: Tensor<D>) -> Tensor<1> {
    let den = mask.clone().sum().clamp_min(1.0);
    (x * mask).sum() / den
}

/// Action loss, L1 over the chunk: mean |â − a*| over the entries where `mask` = 1.
///
/// # Shapes
/// - pred, target, mask: `[B, T, H_a, A]` → `[1]`
pub fn action_l1(pred: Tensor<4>, target: Tensor<4>, mask: Tensor<4>) -> Tensor<1> {
    let [b, t, h, a] = pred.dims();
    assert_shape!(target, [b, t, h, a]);
    assert_shape!(mask, [b, t, h, a]);
    masked_mean((pred - target).abs(), mask)
}

/// Action loss, squared error over the chunk: mean (â − a*)² over the entries where `mask` = 1.
///
/// # Shapes
/// - pred, target, mask: `[B, T, H_a, A]` → `[1]`
pub fn action_l2(pred: Tensor<4>, target: Tensor<4>, mask: Tensor<4>) -> Tensor<1> {
    let [b, t, h, a] = pred.dims();
    assert_shape!(target, [b, t, h, a]);
    assert_shape!(mask, [b, t, h, a]);
    masked_mean((pred - target).powi_scalar(2), mask)
}

/// The action mask with the gripper column (the last of A) weighted by `gripper`, the others by 1.
///
/// # Shapes
/// - mask: `[B, T, H_a, A]` → `[B, T, H_a, A]`
pub fn weight_gripper(mask: Tensor<4>, gripper: f64) -> Tensor<4> {
    if gripper == 1.0 {
        return mask;
    }
    let a = mask.dims()[3];
    let mut w = vec![1.0f32; a];
    w[a - 1] = gripper as f32;
    let w = Tensor::<4>::from_data(TensorData::new(w, [1, 1, 1, a]), &mask.device());
    mask * w
}

/// Pointer loss: cross-entropy of the pointer's weights to each frame's target token, averaged
/// over the chunk steps and the valid frames that have a target.
///
/// # Shapes
/// - weights: `[B, T, H_a, K]` (rows summing to 1); target: `[B, T, K]` one-hot (all zero: no
///   target); frame_mask: `[B, T]` → `[1]`
pub fn pointer_ce(weights: Tensor<4>, target: Tensor<3>, frame_mask: Tensor<2>) -> Tensor<1> {
    let [b, t, _, k] = weights.dims();
    assert_shape!(target, [b, t, k]);
    assert_shape!(frame_mask, [b, t]);
    let target = target * frame_mask.reshape([b, t, 1]);
    let logp = weights.clamp_min(1e-9).log().mean_dim(2).reshape([b, t, k]); // mean over H_a
    let den = target.clone().sum().clamp_min(1.0);
    -(logp * target).sum() / den
}

/// Termination loss: binary cross-entropy of the termination head's logits to each frame's
/// "goal done" target (0 or 1), averaged over the valid frames; computed in the stable form
/// max(x, 0) − x·y + ln(1 + e^(−|x|)).
///
/// # Shapes
/// - logits, target, frame_mask: `[B, T]` → `[1]`
pub fn done_bce(logits: Tensor<2>, target: Tensor<2>, frame_mask: Tensor<2>) -> Tensor<1> {
    let [b, t] = logits.dims();
    assert_shape!(target, [b, t]);
    assert_shape!(frame_mask, [b, t]);
    let soft = logits.clone().abs().neg().exp().log1p();
    let bce = logits.clone().clamp_min(0.0) - logits * target + soft;
    masked_mean(bce, frame_mask)
}

/// Progress loss: cross-entropy of the progress head's logits to each frame's number of subgoals
/// done, averaged over the valid frames.
///
/// # Shapes
/// - logits: `[B, T, C]`; target: `[B, T]` classes in 0 … C−1; frame_mask: `[B, T]` → `[1]`
pub fn progress_ce(logits: Tensor<3>, target: Tensor<2, Int>, frame_mask: Tensor<2>) -> Tensor<1> {
    let [b, t, _] = logits.dims();
    assert_shape!(target, [b, t]);
    assert_shape!(frame_mask, [b, t]);
    let nll = log_softmax(logits, 2)
        .gather(2, target.unsqueeze_dim::<3>(2))
        .reshape([b, t])
        .neg();
    masked_mean(nll, frame_mask)
}

/// Action loss of the discrete head: cross-entropy of the 256-bin logits against the targets'
/// classes, averaged over the entries where `mask` = 1.
///
/// # Shapes
/// - logits: `[B, T, H_a, A, 256]`; target, mask: `[B, T, H_a, A]` → `[1]`
pub fn action_ce(logits: Tensor<5>, target: Tensor<4>, mask: Tensor<4>) -> Tensor<1> {
    let [b, t, h, a] = target.dims();
    assert_shape!(logits, [b, t, h, a, NUM_BINS]);
    assert_shape!(mask, [b, t, h, a]);
    let classes = actions_to_classes(target).unsqueeze_dim::<5>(4);
    let nll = log_softmax(logits, 4)
        .gather(4, classes)
        .squeeze_dim::<4>(4)
        .neg();
    masked_mean(nll, mask)
}

/// Temporal contrastive loss over consecutive slots (τ-scaled cosine, positive = same slot index,
/// negatives = the other slots of the same sample), mean over valid pairs (b, t < T−1, k).
///
/// # Shapes
/// - slots: `[B, T, K, D]`; frame_mask: `[B, T]` → `[1]`
pub fn temporal_contrastive(slots: Tensor<4>, frame_mask: Tensor<2>, tau: f64) -> Tensor<1> {
    let [b, t, k, _] = slots.dims();
    assert_shape!(frame_mask, [b, t]);
    let device = slots.device();
    if t < 2 {
        return Tensor::zeros([1], &device);
    }
    let norm = slots.clone().square().sum_dim(3).sqrt().clamp_min(1e-8);
    let unit = slots / norm;
    let now = unit.clone().narrow(1, 0, t - 1);
    let next = unit.narrow(1, 1, t - 1);
    let sim = now.matmul(next.swap_dims(2, 3)).div_scalar(tau); // [B, T−1, K, K]
    let logp = log_softmax(sim, 3);
    let eye = Tensor::<2>::eye(k, &device).reshape([1, 1, k, k]);
    let pos = (logp * eye).sum_dim(3).squeeze_dim::<3>(3); // [B, T−1, K]
    let pair = frame_mask.clone().narrow(1, 0, t - 1) * frame_mask.narrow(1, 1, t - 1);
    let mask = pair.unsqueeze_dim::<3>(2).repeat_dim(2, k);
    masked_mean(pos.neg(), mask)
}

/// Loose lower bound of [`temporal_contrastive`]: log(1 + (K−1) e^{−2/τ}).
pub fn contrastive_loose_bound(k: usize, tau: f64) -> f64 {
    (1.0 + (k as f64 - 1.0) * (-2.0 / tau).exp()).ln()
}

/// Attainable minimum of [`temporal_contrastive`] (constant simplex slots, τ = 1 in the spec):
/// log(1 + (K−1) e^{−(1 + 1/(K−1))/τ}).
pub fn contrastive_floor(k: usize, tau: f64) -> f64 {
    if k < 2 {
        return 0.0;
    }
    let km1 = k as f64 - 1.0;
    (1.0 + km1 * (-(1.0 + 1.0 / km1) / tau).exp()).ln()
}

/// Windowed reconstruction: element-wise MSE between Ŝ_{t,j} and sg(s_{t+o_j}) over the
/// (b, t, k, j) with 0 ≤ t+o_j < T and both frames valid, and over the D values.
///
/// # Shapes
/// - pred: `[B, T, K, P, D]`; slots: `[B, T, K, D]`; frame_mask: `[B, T]`; offsets: P values → `[1]`
pub fn windowed_recon(
    pred: Tensor<5>,
    slots: Tensor<4>,
    frame_mask: Tensor<2>,
    offsets: &[i64],
) -> Tensor<1> {
    let [b, t, k, p, d] = pred.dims();
    assert_shape!(slots, [b, t, k, d]);
    assert_shape!(frame_mask, [b, t]);
    assert_eq!(offsets.len(), p, "one offset per window slot");
    let device = pred.device();
    let slots = slots.detach();
    let mut targets = Vec::with_capacity(p);
    let mut masks = Vec::with_capacity(p);
    for &o in offsets {
        // target[t] = slots[t + o]; rows with t + o outside [0, T) are zero and masked out.
        let (tgt, m) = shift_time(slots.clone(), frame_mask.clone(), o, &device);
        targets.push(tgt);
        masks.push(m * frame_mask.clone());
    }
    let target = Tensor::stack::<5>(targets, 3); // [B, T, K, P, D]
    let mask = Tensor::stack::<3>(masks, 2) // [B, T, P]
        .reshape([b, t, 1, p, 1])
        .repeat_dim(2, k)
        .repeat_dim(4, d);
    masked_mean((pred - target).square(), mask)
}

/// x shifted along T by `o` (result[t] = x[t + o]), with the validity mask of the source frame
/// (0 where t + o is outside the window).
///
/// # Shapes
/// - x: `[B, T, K, D]`, mask: `[B, T]` → (`[B, T, K, D]`, `[B, T]`)
fn shift_time(x: Tensor<4>, mask: Tensor<2>, o: i64, device: &Device) -> (Tensor<4>, Tensor<2>) {
    let [b, t, k, d] = x.dims();
    let s = o.unsigned_abs() as usize;
    if s >= t {
        return (
            Tensor::zeros([b, t, k, d], device),
            Tensor::zeros([b, t], device),
        );
    }
    if o == 0 {
        return (x, mask);
    }
    let zx = Tensor::zeros([b, s, k, d], device);
    let zm = Tensor::zeros([b, s], device);
    if o > 0 {
        (
            Tensor::cat(vec![x.narrow(1, s, t - s), zx], 1),
            Tensor::cat(vec![mask.narrow(1, s, t - s), zm], 1),
        )
    } else {
        (
            Tensor::cat(vec![zx, x.narrow(1, 0, t - s)], 1),
            Tensor::cat(vec![zm, mask.narrow(1, 0, t - s)], 1),
        )
    }
}

/// Slot reconstruction: element-wise MSE over valid frames, the M positions and the D_tgt values.
///
/// # Shapes
/// - recon, target: `[B, T, M, D_tgt]`; frame_mask: `[B, T]` → `[1]`
pub fn slot_recon(recon: Tensor<4>, target: Tensor<4>, frame_mask: Tensor<2>) -> Tensor<1> {
    let [b, t, m, d] = recon.dims();
    assert_shape!(target, [b, t, m, d]);
    assert_shape!(frame_mask, [b, t]);
    let mask = frame_mask
        .reshape([b, t, 1, 1])
        .repeat_dim(2, m)
        .repeat_dim(3, d);
    masked_mean((recon - target.detach()).square(), mask)
}

/// RGB patches of the images, the targets of L_sa in the tiny config.
///
/// # Shapes
/// - images: `[B, T, 3, H, W]`; grid [gh, gw] dividing H and W
/// - output: `[B, T, gh·gw, (H/gh)·(W/gw)·3]`
pub fn image_patches(images: Tensor<5>, grid: [usize; 2]) -> Tensor<4> {
    let [b, t, c, h, w] = images.dims();
    let [gh, gw] = grid;
    let (ph, pw) = (h / gh, w / gw);
    assert_eq!((ph * gh, pw * gw), (h, w), "grid must divide the image");
    images
        .reshape([b * t, c, gh, ph, gw, pw])
        .permute([0, 2, 4, 3, 5, 1]) // [BT, gh, gw, ph, pw, c]
        .reshape([b, t, gh * gw, ph * pw * c])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_device;
    use burn::tensor::Distribution;

    fn scalar(x: Tensor<1>) -> f64 {
        x.into_scalar::<f32>() as f64
    }

    #[test]
    fn action_l1_is_the_masked_mean_abs_error() {
        let (_guard, device) = test_device();
        let pred = Tensor::<4>::from_floats([[[[1.0, 2.0], [3.0, 4.0]]]], &device);
        let target = Tensor::<4>::from_floats([[[[0.0, 0.0], [0.0, 10.0]]]], &device);
        let all = Tensor::<4>::ones([1, 1, 2, 2], &device);
        assert!((scalar(action_l1(pred.clone(), target.clone(), all)) - 3.0).abs() < 1e-6);
        let some = Tensor::<4>::from_floats([[[[1.0, 0.0], [1.0, 0.0]]]], &device);
        assert!((scalar(action_l1(pred, target, some)) - 2.0).abs() < 1e-6);
    }

    #[test]
    fn action_l2_is_the_masked_mean_squared_error() {
        let (_guard, device) = test_device();
        let pred = Tensor::<4>::from_floats([[[[1.0, 2.0], [3.0, 4.0]]]], &device);
        let target = Tensor::<4>::from_floats([[[[0.0, 0.0], [0.0, 10.0]]]], &device);
        let all = Tensor::<4>::ones([1, 1, 2, 2], &device);
        // (1 + 4 + 9 + 36) / 4.
        assert!((scalar(action_l2(pred.clone(), target.clone(), all)) - 12.5).abs() < 1e-5);
        let some = Tensor::<4>::from_floats([[[[1.0, 0.0], [1.0, 0.0]]]], &device);
        assert!((scalar(action_l2(pred, target, some)) - 5.0).abs() < 1e-5);
    }

    #[test]
    fn pointer_ce_is_the_mean_log_weight_of_the_targets() {
        let (_guard, device) = test_device();
        // B = 1, T = 3, H_a = 2, K = 2. Frame 0 targets token 1 (weights 0.5 and 0.25), frame 1
        // has no target, frame 2 targets token 0 but is padding.
        let w = Tensor::<4>::from_floats(
            [[
                [[0.5, 0.5], [0.75, 0.25]],
                [[0.9, 0.1], [0.9, 0.1]],
                [[0.01, 0.99], [0.01, 0.99]],
            ]],
            &device,
        );
        let target = Tensor::<3>::from_floats([[[0.0, 1.0], [0.0, 0.0], [1.0, 0.0]]], &device);
        let mask = Tensor::<2>::from_floats([[1.0, 1.0, 0.0]], &device);
        let want = -(0.5f64.ln() + 0.25f64.ln()) / 2.0;
        let got = scalar(pointer_ce(w.clone(), target.clone(), mask));
        assert!((got - want).abs() < 1e-5, "{got} vs {want}");
        // With frame 2 valid, its −ln 0.01 joins the mean over the two targeted frames.
        let all = Tensor::<2>::ones([1, 3], &device);
        let want = (want - 0.01f64.ln()) / 2.0;
        let got = scalar(pointer_ce(w.clone(), target, all.clone()));
        assert!((got - want).abs() < 1e-5, "{got} vs {want}");
        // No targets at all: zero.
        let none = Tensor::<3>::zeros([1, 3, 2], &device);
        assert_eq!(scalar(pointer_ce(w, none, all)), 0.0);
    }

    #[test]
    fn progress_ce_is_the_mean_nll_of_the_valid_frames() {
        let (_guard, device) = test_device();
        // B = 1, T = 3, C = 3: frame 0 uniform (target 2), frame 1 sure of its target 0,
        // frame 2 padding.
        let logits = Tensor::<3>::from_floats(
            [[[0.0, 0.0, 0.0], [20.0, 0.0, 0.0], [0.0, 5.0, 0.0]]],
            &device,
        );
        let target = Tensor::<2, Int>::from_ints([[2, 0, 0]], &device);
        let mask = Tensor::<2>::from_floats([[1.0, 1.0, 0.0]], &device);
        let want = 3f64.ln() / 2.0;
        let got = scalar(progress_ce(logits.clone(), target.clone(), mask));
        assert!((got - want).abs() < 1e-5, "{got} vs {want}");
        // Frame 2 valid: −log softmax(0, 5, 0)[0] = ln(2 + e⁵) joins the mean.
        let all = Tensor::<2>::ones([1, 3], &device);
        let want = (3f64.ln() + (2.0 + 5f64.exp()).ln()) / 3.0;
        let got = scalar(progress_ce(logits, target, all));
        assert!((got - want).abs() < 1e-4, "{got} vs {want}");
    }

    #[test]
    fn done_bce_is_the_mean_binary_nll_of_the_valid_frames() {
        let (_guard, device) = test_device();
        // Frame 0: logit 0 (p = ½), target 1; frame 1: logit 30 (sure), target 1;
        // frame 2: logit −2, target 0; frame 3: padding with a huge logit on the wrong side.
        let logits = Tensor::<2>::from_floats([[0.0, 30.0, -2.0, 1e4]], &device);
        let target = Tensor::<2>::from_floats([[1.0, 1.0, 0.0, 0.0]], &device);
        let mask = Tensor::<2>::from_floats([[1.0, 1.0, 1.0, 0.0]], &device);
        let want = (2f64.ln() + (1.0 + (-30f64).exp()).ln() + (1.0 + (-2f64).exp()).ln()) / 3.0;
        let got = scalar(done_bce(logits.clone(), target.clone(), mask));
        assert!((got - want).abs() < 1e-5, "{got} vs {want}");
        // The padded frame counted: −ln σ(−10⁴) = 10⁴ joins the mean, finite.
        let all = Tensor::<2>::ones([1, 4], &device);
        let got = scalar(done_bce(logits, target, all));
        let want = (want * 3.0 + 1e4) / 4.0;
        assert!((got - want).abs() < 1e-2, "{got} vs {want}");
    }

    #[test]
    fn gripper_weight_scales_the_last_column_of_the_weighted_mean() {
        let (_g, device) = test_device();
        // |errors| 1 and 4 on the arm, 2 and 8 on the gripper (A = 2: arm, gripper).
        let pred = Tensor::<4>::from_floats([[[[1.0, 2.0], [4.0, 8.0]]]], &device);
        let target = Tensor::<4>::zeros([1, 1, 2, 2], &device);
        let all = Tensor::<4>::ones([1, 1, 2, 2], &device);
        let plain = weight_gripper(all.clone(), 1.0);
        assert!((scalar(action_l1(pred.clone(), target.clone(), plain)) - 3.75).abs() < 1e-6);
        // Weight 3: (1 + 4 + 3·(2 + 8)) / (2 + 3·2) = 35 / 8.
        let w = weight_gripper(all.clone(), 3.0);
        assert_eq!(
            w.clone().into_data().try_to_vec::<f32>().unwrap(),
            vec![1.0, 3.0, 1.0, 3.0]
        );
        assert!((scalar(action_l1(pred.clone(), target.clone(), w)) - 35.0 / 8.0).abs() < 1e-6);
        // Masked entries stay out whatever the weight.
        let some = Tensor::<4>::from_floats([[[[1.0, 1.0], [0.0, 0.0]]]], &device);
        let w = weight_gripper(some, 3.0);
        assert!((scalar(action_l1(pred, target, w)) - 7.0 / 4.0).abs() < 1e-6);
    }

    #[test]
    fn action_ce_is_low_for_confident_right_bins() {
        let (_guard, device) = test_device();
        let target = Tensor::<4>::from_floats([[[[0.0, 1.0]]]], &device);
        let mask = Tensor::<4>::ones([1, 1, 1, 2], &device);
        let uniform = Tensor::<5>::zeros([1, 1, 1, 2, NUM_BINS], &device);
        let ce = scalar(action_ce(uniform, target.clone(), mask.clone()));
        assert!((ce - (NUM_BINS as f64).ln()).abs() < 1e-4);
        let classes = actions_to_classes(target.clone())
            .into_data()
            .try_to_vec_as::<i64>()
            .unwrap();
        let mut data = vec![0.0f32; 2 * NUM_BINS];
        data[classes[0] as usize] = 50.0;
        data[NUM_BINS + classes[1] as usize] = 50.0;
        let sharp = Tensor::<5>::from_data(TensorData::new(data, [1, 1, 1, 2, NUM_BINS]), &device);
        assert!(scalar(action_ce(sharp, target, mask)) < 1e-6);
    }

    #[test]
    fn contrastive_never_below_the_loose_bound_on_random_slots() {
        let (_guard, device) = test_device();
        device.seed(5);
        for k in [2, 4, 8] {
            let slots = Tensor::<4>::random([3, 5, k, 16], Distribution::Normal(0.0, 1.0), &device);
            let mask = Tensor::<2>::ones([3, 5], &device);
            let l = scalar(temporal_contrastive(slots, mask, 1.0));
            assert!(l >= contrastive_loose_bound(k, 1.0) - 1e-6, "K={k}: {l}");
            assert!(l >= contrastive_floor(k, 1.0) - 1e-6, "K={k}: {l}");
        }
    }

    /// Constant slots forming a regular simplex: e_k − 1/K, embedded in D = K + 3 dims.
    fn simplex_slots(k: usize, t: usize, device: &Device) -> Tensor<4> {
        let d = k + 3;
        let mut data = Vec::new();
        for _ in 0..t {
            for i in 0..k {
                for j in 0..d {
                    let one = if i == j { 1.0 } else { 0.0 };
                    data.push(if j < k { one - 1.0 / k as f32 } else { 0.0 });
                }
            }
        }
        Tensor::from_data(TensorData::new(data, [1, t, k, d]), device)
    }

    #[test]
    fn contrastive_reaches_the_floor_for_simplex_slots() {
        let (_guard, device) = test_device();
        let mask = Tensor::<2>::ones([1, 4], &device);
        for (k, want) in [(8, 1.173), (16, 1.819)] {
            let l = scalar(temporal_contrastive(
                simplex_slots(k, 4, &device),
                mask.clone(),
                1.0,
            ));
            assert!((l - contrastive_floor(k, 1.0)).abs() < 1e-5, "K={k}: {l}");
            assert!((contrastive_floor(k, 1.0) - want).abs() < 1e-3);
        }
        // At K = 2 the simplex has cosine −1, so the loose bound is reached too.
        let l = scalar(temporal_contrastive(
            simplex_slots(2, 4, &device),
            mask,
            1.0,
        ));
        assert!((l - contrastive_loose_bound(2, 1.0)).abs() < 1e-5, "{l}");
        assert!((contrastive_floor(2, 1.0) - contrastive_loose_bound(2, 1.0)).abs() < 1e-12);
    }

    #[test]
    fn contrastive_ignores_invalid_pairs() {
        let (_guard, device) = test_device();
        let good = simplex_slots(4, 3, &device);
        let noise = Tensor::<4>::random([1, 2, 4, 7], Distribution::Normal(0.0, 1.0), &device);
        let slots = Tensor::cat(vec![good, noise], 1);
        let mask = Tensor::<2>::from_floats([[1.0, 1.0, 1.0, 0.0, 0.0]], &device);
        let l = scalar(temporal_contrastive(slots, mask, 1.0));
        assert!((l - contrastive_floor(4, 1.0)).abs() < 1e-5);
    }

    #[test]
    fn windowed_recon_is_zero_for_exact_predictions_and_masks_the_edges() {
        let (_guard, device) = test_device();
        let (b, t, k, d) = (2, 5, 3, 4);
        let slots = Tensor::<4>::random([b, t, k, d], Distribution::Normal(0.0, 1.0), &device);
        let offsets = [-2i64, -1, 0, 1];
        let mask = Tensor::<2>::ones([b, t], &device);
        // Build the exact prediction by hand: pred[t, j] = slots[t + o_j] (garbage outside).
        let s = slots.clone().into_data().try_to_vec::<f32>().unwrap();
        let mut data = Vec::new();
        for bi in 0..b {
            for ti in 0..t {
                for ki in 0..k {
                    for &o in &offsets {
                        for di in 0..d {
                            let src = ti as i64 + o;
                            data.push(if (0..t as i64).contains(&src) {
                                s[((bi * t + src as usize) * k + ki) * d + di]
                            } else {
                                123.0
                            });
                        }
                    }
                }
            }
        }
        let pred = Tensor::<5>::from_data(TensorData::new(data, [b, t, k, 4, d]), &device);
        let l = scalar(windowed_recon(pred.clone(), slots.clone(), mask, &offsets));
        assert!(l < 1e-10, "{l}");
        // Off by one everywhere: error 1 per value over valid entries.
        let l = scalar(windowed_recon(
            pred.add_scalar(1.0),
            slots,
            Tensor::<2>::ones([b, t], &device),
            &offsets,
        ));
        assert!((l - 1.0).abs() < 1e-5, "{l}");
    }

    #[test]
    fn slot_recon_and_patches() {
        let (_guard, device) = test_device();
        let img = Tensor::<5>::random([1, 2, 3, 4, 6], Distribution::Default, &device);
        let patches = image_patches(img.clone(), [2, 3]);
        assert_eq!(patches.dims(), [1, 2, 6, 12]);
        // Patch (1, 2) of frame 1, pixel (0, 1), channel 2 = image[.., 1, 2, 2, 5].
        let v: f32 = patches.clone().slice(s![0, 1, 5, 5]).into_scalar();
        let want: f32 = img.slice(s![0, 1, 2, 2, 5]).into_scalar();
        assert_eq!(v, want);
        let mask = Tensor::<2>::ones([1, 2], &device);
        assert!(scalar(slot_recon(patches.clone(), patches.clone(), mask.clone())) < 1e-12);
        let l = scalar(slot_recon(patches.clone().add_scalar(0.5), patches, mask));
        assert!((l - 0.25).abs() < 1e-6);
    }
}
