//! Slots ↔ objects (the reference's oracle-label binding, libero-mem-reference.md §3 "Oracle
//! subgoal embeddings"): each visible object's box is matched to one slot by the Hungarian
//! algorithm on the soft IoU of the slot's attention mask with the box; the slot takes that
//! object's label, every other slot the `"0"` label.
//!
//! The reference matches boxes predicted from the slots to the recorded boxes; we have no box
//! head, so the slot-attention masks stand in for the predictions. Unseen objects (zero box) are
//! left out of the frame's matching, so their labels reach no slot while they are hidden.

use burn::prelude::*;
use pathfinding::kuhn_munkres::kuhn_munkres;
use pathfinding::matrix::Matrix;

use crate::error::{ModelError, Result};

/// Integer scale of the IoU weights given to the Hungarian solver (it needs an ordered type).
const SCALE: f32 = 1.0e6;

/// Soft IoU of one slot's mask over the token grid with a box: Σ a·b / (Σ a + Σ b − Σ a·b),
/// b = 1 on the tokens whose centre lies inside the box.
///
/// - mask: `[rows · cols]` (row-major, each value in [0, 1]); bbox: `[x, y, w, h]` in [0, 1]
///   of the upright image (x right, y down)
pub fn soft_iou(mask: &[f32], grid: [usize; 2], bbox: [f32; 4]) -> f32 {
    let [rows, cols] = grid;
    let [x, y, w, h] = bbox;
    let (mut inter, mut area_a, mut area_b) = (0.0f32, 0.0f32, 0.0f32);
    for r in 0..rows {
        let cy = (r as f32 + 0.5) / rows as f32;
        let in_y = cy >= y && cy <= y + h;
        for c in 0..cols {
            let a = mask[r * cols + c];
            area_a += a;
            let cx = (c as f32 + 0.5) / cols as f32;
            if in_y && cx >= x && cx <= x + w {
                area_b += 1.0;
                inter += a;
            }
        }
    }
    let union = area_a + area_b - inter;
    if union > 0.0 { inter / union } else { 0.0 }
}

/// Whether an object's box says it is seen (a zero box marks an unseen object).
pub fn is_seen(bbox: [f32; 4]) -> bool {
    bbox[2] > 0.0 && bbox[3] > 0.0
}

/// The object each slot is matched to (None: unmatched), maximising the summed soft IoU; every
/// seen object gets one slot while there are slots left (with more seen objects than slots,
/// the objects that fit the slots best win).
///
/// - masks: K slots' masks, each `[rows · cols]`; boxes: J objects' `[x, y, w, h]`
pub fn match_slots(masks: &[Vec<f32>], grid: [usize; 2], boxes: &[[f32; 4]]) -> Vec<Option<usize>> {
    let k = masks.len();
    let seen: Vec<usize> = (0..boxes.len()).filter(|&j| is_seen(boxes[j])).collect();
    let mut out = vec![None; k];
    if k == 0 || seen.is_empty() {
        return out;
    }
    let weight = |j: usize, s: usize| (soft_iou(&masks[s], grid, boxes[j]) * SCALE).round() as i64;
    if seen.len() <= k {
        // Rows: objects, columns: slots.
        let m = Matrix::from_fn(seen.len(), k, |(r, s)| weight(seen[r], s));
        let (_, cols) = kuhn_munkres(&m);
        for (r, s) in cols.into_iter().enumerate() {
            out[s] = Some(seen[r]);
        }
    } else {
        // Rows: slots, columns: objects.
        let m = Matrix::from_fn(k, seen.len(), |(s, c)| weight(seen[c], s));
        let (_, cols) = kuhn_munkres(&m);
        for (s, c) in cols.into_iter().enumerate() {
            out[s] = Some(seen[c]);
        }
    }
    out
}

/// For every slot of N frames, the row of its label among J objects' labels followed by the
/// `"0"` label (row J): the object matched to it ([`match_slots`]) or J.
///
/// # Shapes
/// - masks: `[N, K, M]` with M = rows · cols; boxes: `[N, J, 4]`
/// - output: `[N, K]` (values in 0..=J)
pub fn label_rows(masks: Tensor<3>, boxes: Tensor<3>, grid: [usize; 2]) -> Result<Tensor<2, Int>> {
    let [n, k, m] = masks.dims();
    let [n2, j, four] = boxes.dims();
    if n2 != n || four != 4 || m != grid[0] * grid[1] {
        return Err(ModelError::Input(format!(
            "object boxes {:?} for slot masks {:?} over a {}×{} grid: expected [{n}, J, 4]",
            boxes.dims(),
            masks.dims(),
            grid[0],
            grid[1]
        )));
    }
    let device = masks.device();
    let host = |t: Tensor<3>, what: &str| {
        t.into_data()
            .convert::<f32>()
            .try_to_vec::<f32>()
            .map_err(|e| ModelError::Input(format!("{what}: {e:?}")))
    };
    let mv = host(masks.detach(), "slot masks")?;
    let bv = host(boxes, "object boxes")?;
    let mut rows = Vec::with_capacity(n * k);
    for f in 0..n {
        let frame: Vec<Vec<f32>> = (0..k)
            .map(|s| mv[(f * k + s) * m..(f * k + s + 1) * m].to_vec())
            .collect();
        let bx: Vec<[f32; 4]> = (0..j)
            .map(|o| {
                let b = &bv[(f * j + o) * 4..(f * j + o + 1) * 4];
                [b[0], b[1], b[2], b[3]]
            })
            .collect();
        rows.extend(
            match_slots(&frame, grid, &bx)
                .into_iter()
                .map(|o| o.unwrap_or(j) as i64),
        );
    }
    Ok(Tensor::from_data(TensorData::new(rows, [n, k]), &device))
}

/// Per-slot label ids: row `rows[n, k]` of `ids[n]` for every slot.
///
/// # Shapes
/// - ids: `[N, J + 1, L]`; rows: `[N, K]` (values in 0..=J)
/// - output: `[N, K, L]`
pub fn gather_labels(ids: Tensor<3, Int>, rows: Tensor<2, Int>) -> Tensor<3, Int> {
    let [n, _, l] = ids.dims();
    let [_, k] = rows.dims();
    let index = rows.reshape([n, k, 1]).repeat_dim(2, l);
    ids.gather(1, index)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_device;

    /// A 4×4 grid mask with weight 1 on the given (row, col) tokens.
    fn mask(on: &[(usize, usize)]) -> Vec<f32> {
        let mut m = vec![0.0; 16];
        for &(r, c) in on {
            m[r * 4 + c] = 1.0;
        }
        m
    }

    #[test]
    fn soft_iou_of_a_mask_equal_to_its_box_is_one_and_of_a_disjoint_one_zero() {
        // Box over the top-left 2×2 tokens (centres at 0.125 and 0.375).
        let b = [0.0, 0.0, 0.5, 0.5];
        let top_left = mask(&[(0, 0), (0, 1), (1, 0), (1, 1)]);
        assert_eq!(soft_iou(&top_left, [4, 4], b), 1.0);
        assert_eq!(soft_iou(&mask(&[(3, 3)]), [4, 4], b), 0.0);
        // Half the box covered: 2 / (2 + 4 − 2).
        assert_eq!(soft_iou(&mask(&[(0, 0), (0, 1)]), [4, 4], b), 0.5);
        // A mask spread over everything: 4 / 16.
        assert_eq!(soft_iou(&[1.0; 16], [4, 4], b), 0.25);
    }

    #[test]
    fn each_seen_object_goes_to_the_slot_over_it() {
        let masks = vec![
            mask(&[(3, 3)]),                 // slot 0: bottom right
            mask(&[(0, 0), (0, 1)]),         // slot 1: top left
            mask(&[(2, 0), (3, 0), (3, 1)]), // slot 2: bottom left
        ];
        let boxes = [
            [0.0, 0.5, 0.5, 0.5],  // object 0: bottom left
            [0.0, 0.0, 0.5, 0.25], // object 1: top left, one row
            [0.0; 4],              // object 2: unseen
        ];
        assert_eq!(
            match_slots(&masks, [4, 4], &boxes),
            vec![None, Some(1), Some(0)]
        );
        // Nothing seen: no slot is matched.
        assert_eq!(match_slots(&masks, [4, 4], &[[0.0; 4]]), vec![None; 3]);
    }

    #[test]
    fn the_matching_is_one_to_one_even_when_one_slot_fits_two_objects_best() {
        // Slot 0 covers both objects; slot 1 only object 1: object 0 must go to slot 0.
        let masks = vec![mask(&[(0, 0), (0, 3)]), mask(&[(0, 3)])];
        let boxes = [[0.0, 0.0, 0.25, 0.25], [0.75, 0.0, 0.25, 0.25]];
        assert_eq!(match_slots(&masks, [4, 4], &boxes), vec![Some(0), Some(1)]);
        // More seen objects than slots: the slot takes the object it fits best.
        let one = vec![mask(&[(0, 3)])];
        assert_eq!(match_slots(&one, [4, 4], &boxes), vec![Some(1)]);
    }

    #[test]
    fn label_rows_and_gather_give_each_slot_its_objects_label_and_the_rest_zero() {
        let (_guard, device) = test_device();
        // One frame, K = 3 slots, J = 2 objects: slot 2 over object 0, slot 0 over object 1.
        let masks: Vec<f32> = [mask(&[(3, 3)]), mask(&[(1, 1)]), mask(&[(0, 0)])].concat();
        let masks = Tensor::<3>::from_data(TensorData::new(masks, [1, 3, 16]), &device);
        let boxes = Tensor::<3>::from_data(
            TensorData::new(
                vec![0.0, 0.0, 0.25, 0.25, 0.75, 0.75, 0.25, 0.25],
                [1, 2, 4],
            ),
            &device,
        );
        let rows = label_rows(masks, boxes, [4, 4]).unwrap();
        assert_eq!(
            rows.clone()
                .into_data()
                .convert::<i64>()
                .try_to_vec::<i64>()
                .unwrap(),
            vec![1, 2, 0]
        );
        // Labels of 2 tokens: object 0 = [5, 6], object 1 = [7, 8], "0" = [1, 0].
        let ids = Tensor::<3, Int>::from_data(
            TensorData::new(vec![5i64, 6, 7, 8, 1, 0], [1, 3, 2]),
            &device,
        );
        let per_slot = gather_labels(ids, rows);
        assert_eq!(per_slot.dims(), [1, 3, 2]);
        assert_eq!(
            per_slot
                .into_data()
                .convert::<i64>()
                .try_to_vec::<i64>()
                .unwrap(),
            vec![7, 8, 1, 0, 5, 6]
        );
    }

    #[test]
    fn boxes_that_do_not_fit_the_masks_are_an_error() {
        let (_guard, device) = test_device();
        let masks = Tensor::<3>::zeros([2, 3, 16], &device);
        let boxes = Tensor::<3>::zeros([1, 2, 4], &device);
        let e = label_rows(masks, boxes, [4, 4]).unwrap_err().to_string();
        assert!(e.contains("expected [2, J, 4]"), "{e}");
    }
}
