//! The data that flows between the shared model and its variants: carried memory (windows and
//! streaming), a window's tokens and intermediate results, and the shared modules a variant reads.

use std::collections::VecDeque;

use burn::prelude::*;

use crate::error::{ModelError, Result};
use crate::slot_ssm::SlotSsmState;
use crate::text::TextEncoder;

/// Visual token types added before the decoder (rows of `PolicyModel::token_type`).
pub(crate) const TYPE_RELATION: usize = 0;
pub(crate) const TYPE_SLOT: usize = 1;
pub(crate) const TYPE_PATCH: usize = 2;

/// Memory carried from one window to the next of the same episodes (truncated BPTT, model.md
/// §10), detached: the last frame's slots, the SlotSSM state, and for SlotVLA(h)/dense(h) the
/// tokens of the last h − 1 frames. An empty carry starts every lane at an episode start;
/// `fresh` marks the lanes that start a new episode at this window although others continue
/// (their carried memory is ignored: learned initial slots, zero SSM state, no history).
#[derive(Clone, Debug, Default)]
pub struct Carry {
    /// Slots of the last frame `[B, K, D]` (slot variants).
    pub slots: Option<Tensor<3>>,
    /// SlotSSM state after the last frame (e_slotssm).
    pub ssm: Option<SlotSsmState>,
    /// Decoder tokens of the last h − 1 frames `[B, h−1, V₁, D_dec]` (history variants).
    pub history: Option<Tensor<4>>,
    /// `[B, h−1]`: which of those frames belong to the episode (false = before its start).
    pub history_valid: Option<Tensor<2, Bool>>,
    /// `[B]`: lanes that start a new episode at this window (None: none do).
    pub fresh: Option<Tensor<1, Bool>>,
}

impl Carry {
    /// The same memory with `fresh` lanes marked as starting a new episode.
    pub fn with_fresh(self, fresh: Tensor<1, Bool>) -> Self {
        Carry {
            fresh: Some(fresh),
            ..self
        }
    }
}

/// The oracle subgoal as token ids, and how its rows reach the slots. `R` = 4 for windows
/// (`[B, T, …]`), 3 for one streamed step (`[1, …]`).
#[derive(Clone, Debug)]
pub struct Subgoal<const R: usize> {
    /// Token ids `[…, G, L_sg]`: G = 1 (shared by every slot) or K (slot k reads row k); with
    /// `boxes`, G = J + 1: J objects' labels, then the `"0"` label.
    pub ids: Tensor<R, Int>,
    /// Object boxes `[…, J, 4]` (`[x, y, w, h]` in [0, 1] of the upright frame, zero when
    /// unseen): each slot reads the label of the object its attention mask is matched to
    /// ([`crate::matching`]), the others row J. None: the ids are per slot or shared.
    pub boxes: Option<Tensor<R>>,
}

impl<const R: usize> From<Tensor<R, Int>> for Subgoal<R> {
    fn from(ids: Tensor<R, Int>) -> Self {
        Subgoal { ids, boxes: None }
    }
}

impl Subgoal<4> {
    /// Frames `start..start + len` of every window.
    pub fn narrow_time(self, start: usize, len: usize) -> Self {
        Subgoal {
            ids: self.ids.narrow(1, start, len),
            boxes: self.boxes.map(|x| x.narrow(1, start, len)),
        }
    }

    /// The rows of `[B, T, …]` flattened to `[B · T, …]`.
    pub fn frames(self) -> Subgoal<3> {
        let [b, t, g, l] = self.ids.dims();
        Subgoal {
            ids: self.ids.reshape([b * t, g, l]),
            boxes: self.boxes.map(|x| {
                let [b, t, j, c] = x.dims();
                x.reshape([b * t, j, c])
            }),
        }
    }
}

/// The state a streaming policy carries from step to step (reset per episode).
#[derive(Clone, Debug, Default)]
pub struct Memory {
    /// Slots of the previous frame `[1, K, D]` (slot variants).
    pub slots: Option<Tensor<3>>,
    /// SlotSSM state (e_slotssm).
    pub ssm: Option<SlotSsmState>,
    /// Decoder tokens of the last h frames, oldest first, each `[1, V₁, D_dec]` (h > 1 only).
    pub history: VecDeque<Tensor<3>>,
    /// Slot-attention masks of the latest frame `[1, K, M]` (slot variants).
    pub masks: Option<Tensor<3>>,
}

impl Memory {
    /// Floats held (slots + SSM states + history tokens).
    pub fn num_floats(&self) -> usize {
        self.slots.as_ref().map_or(0, |t| t.shape().num_elements())
            + self.ssm.as_ref().map_or(0, SlotSsmState::num_floats)
            + self
                .history
                .iter()
                .map(|t| t.shape().num_elements())
                .sum::<usize>()
    }
}

/// What a variant computes over a window besides the decoder tokens.
#[derive(Clone, Debug, Default)]
pub struct WindowParts {
    /// Slots s `[B, T, K, D]` (slot variants).
    pub slots: Option<Tensor<4>>,
    /// Slot attention masks `[B, T, K, M]` (slot variants).
    pub masks: Option<Tensor<4>>,
    /// SlotSSM predictions ŝ_{t+1} `[B, T, K, D]` (e_slotssm).
    pub predicted: Option<Tensor<4>>,
    /// Windowed predictions Ŝ `[B, T, K, P, D]` (e_slotssm).
    pub window: Option<Tensor<5>>,
}

/// The decoder's visual input of a window.
#[derive(Clone, Debug)]
pub struct WindowTokens {
    /// Visual tokens per frame `[B·T, V, D_dec]` (V = h·V₁ with a history).
    pub tokens: Tensor<3>,
    /// Padding of the history `[B·T, V]` (true = frame before the window start).
    pub pad: Option<Tensor<2, Bool>>,
    /// The variant's intermediate results (for the losses and inspection).
    pub parts: WindowParts,
    /// The memory after the window, detached.
    pub carry: Carry,
}

/// Shared modules a variant reads but does not own.
#[derive(Clone, Copy, Debug)]
pub struct Shared<'a> {
    /// Visual token type embeddings `[3, D_dec]`.
    pub token_type: &'a Tensor<2>,
    /// Word embeddings (for subgoal texts).
    pub text: &'a TextEncoder,
}

impl Shared<'_> {
    /// Embedding of one visual token type.
    ///
    /// # Shapes
    /// - output: `[1, 1, D_dec]`
    pub(crate) fn type_embedding(&self, kind: usize) -> Tensor<3> {
        self.token_type.clone().narrow(0, kind, 1).unsqueeze_dim(0)
    }
}

/// A tensor in a serialisable form (carried memory in checkpoints).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TensorRecord<T> {
    /// Shape.
    pub shape: Vec<usize>,
    /// Values, row-major.
    pub data: Vec<T>,
}

fn float_record<const D: usize>(t: &Tensor<D>) -> TensorRecord<f32> {
    TensorRecord {
        shape: t.dims().to_vec(),
        data: t.clone().try_to_vec_as::<f32>().expect("readable tensor"),
    }
}

fn float_tensor<const D: usize>(r: &TensorRecord<f32>, device: &Device) -> Result<Tensor<D>> {
    let shape: [usize; D] = r.shape.as_slice().try_into().map_err(|_| {
        ModelError::Input(format!(
            "carried tensor of rank {}, expected {D}",
            r.shape.len()
        ))
    })?;
    if shape.iter().product::<usize>() != r.data.len() {
        return Err(ModelError::Input(format!(
            "carried tensor {:?} with {} values",
            r.shape,
            r.data.len()
        )));
    }
    Ok(Tensor::from_data(
        TensorData::new(r.data.clone(), shape),
        device,
    ))
}

/// [`Carry`] as saved with a checkpoint (so that a resumed run continues with the memory the
/// uninterrupted run had).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CarryRecord {
    /// Slots `[B, K, D]`.
    pub slots: Option<TensorRecord<f32>>,
    /// Per SlotSSM block: `h [B·K, E, S]` and `conv [B·K, E, d_conv − 1]`.
    pub ssm: Option<Vec<(TensorRecord<f32>, TensorRecord<f32>)>>,
    /// History tokens `[B, h−1, V₁, D_dec]`.
    pub history: Option<TensorRecord<f32>>,
    /// History validity `[B, h−1]`.
    pub history_valid: Option<TensorRecord<bool>>,
}

impl Carry {
    /// Lanes `start..start + len` of a carry over `lanes` lanes: `[B, …]` tensors narrowed on
    /// their first axis, the SSM state's `[B·K, …]` rows of those lanes (data-parallel shards).
    pub fn lanes(&self, start: usize, len: usize, lanes: usize) -> Carry {
        fn rows<const D: usize>(
            t: &Tensor<D>,
            start: usize,
            len: usize,
            lanes: usize,
        ) -> Tensor<D> {
            let per = t.dims()[0] / lanes.max(1);
            t.clone().narrow(0, start * per, len * per)
        }
        Carry {
            slots: self.slots.as_ref().map(|t| rows(t, start, len, lanes)),
            ssm: self.ssm.as_ref().map(|s| SlotSsmState {
                blocks: s
                    .blocks
                    .iter()
                    .map(|b| crate::mamba::MambaState {
                        h: rows(&b.h, start, len, lanes),
                        conv: rows(&b.conv, start, len, lanes),
                    })
                    .collect(),
            }),
            history: self.history.as_ref().map(|t| rows(t, start, len, lanes)),
            history_valid: self
                .history_valid
                .as_ref()
                .map(|t| t.clone().narrow(0, start, len)),
            fresh: self.fresh.as_ref().map(|t| t.clone().narrow(0, start, len)),
        }
    }

    /// Joins the carries of consecutive lane ranges into one (the inverse of [`Carry::lanes`]);
    /// an error when the parts do not carry the same kinds of memory.
    pub fn cat_lanes(parts: Vec<Carry>) -> Result<Carry> {
        fn join<T>(parts: Vec<Option<T>>, what: &str) -> Result<Option<Vec<T>>> {
            let n = parts.len();
            let some: Vec<T> = parts.into_iter().flatten().collect();
            match some.len() {
                0 => Ok(None),
                k if k == n => Ok(Some(some)),
                k => Err(ModelError::Input(format!(
                    "carried {what}: {k} of {n} lane groups have it"
                ))),
            }
        }
        let mut slots = vec![];
        let mut ssm = vec![];
        let mut history = vec![];
        let mut valid = vec![];
        let mut fresh = vec![];
        for c in parts {
            slots.push(c.slots);
            ssm.push(c.ssm);
            history.push(c.history);
            valid.push(c.history_valid);
            fresh.push(c.fresh);
        }
        let ssm = join(ssm, "SSM state")?
            .map(|states| -> Result<SlotSsmState> {
                let blocks = states[0].blocks.len();
                if states.iter().any(|s| s.blocks.len() != blocks) {
                    return Err(ModelError::Input(
                        "carried SSM state: lane groups differ in block count".into(),
                    ));
                }
                Ok(SlotSsmState {
                    blocks: (0..blocks)
                        .map(|i| crate::mamba::MambaState {
                            h: Tensor::cat(
                                states.iter().map(|s| s.blocks[i].h.clone()).collect(),
                                0,
                            ),
                            conv: Tensor::cat(
                                states.iter().map(|s| s.blocks[i].conv.clone()).collect(),
                                0,
                            ),
                        })
                        .collect(),
                })
            })
            .transpose()?;
        Ok(Carry {
            slots: join(slots, "slots")?.map(|v| Tensor::cat(v, 0)),
            ssm,
            history: join(history, "history")?.map(|v| Tensor::cat(v, 0)),
            history_valid: join(valid, "history validity")?.map(|v| Tensor::cat(v, 0)),
            fresh: join(fresh, "episode starts")?.map(|v| Tensor::cat(v, 0)),
        })
    }

    /// The lanes `picked` of a carry over `lanes` lanes, in that order (a lane pool's batch).
    pub fn pick_lanes(&self, picked: &[usize], lanes: usize) -> Result<Carry> {
        Carry::cat_lanes(picked.iter().map(|&l| self.lanes(l, 1, lanes)).collect())
    }

    /// A carry over `lanes` lanes whose lanes `picked` are `part`'s lanes, in order, and whose
    /// others are this carry's (a lane pool after a batch advanced `picked`). Where this carry
    /// is empty (no lane has run yet), the others copy `part`'s first lane: placeholders, since
    /// a lane that has not run starts its episode and its memory is never read. Not `fresh`.
    pub fn put_lanes(&self, lanes: usize, picked: &[usize], part: &Carry) -> Result<Carry> {
        let n = picked.len();
        let rows = (0..lanes)
            .map(|l| match picked.iter().position(|&p| p == l) {
                Some(i) => part.lanes(i, 1, n),
                None if self.is_empty() => part.lanes(0, 1, n),
                None => self.lanes(l, 1, lanes),
            })
            .map(|c| Carry { fresh: None, ..c })
            .collect();
        Carry::cat_lanes(rows)
    }

    /// Whether nothing is carried (every lane starts fresh).
    pub fn is_empty(&self) -> bool {
        self.slots.is_none() && self.ssm.is_none() && self.history.is_none()
    }

    /// The serialisable form (`fresh` is not kept: it belongs to the next batch).
    pub fn to_record(&self) -> CarryRecord {
        CarryRecord {
            slots: self.slots.as_ref().map(float_record),
            ssm: self.ssm.as_ref().map(|s| {
                s.blocks
                    .iter()
                    .map(|b| (float_record(&b.h), float_record(&b.conv)))
                    .collect()
            }),
            history: self.history.as_ref().map(float_record),
            history_valid: self.history_valid.as_ref().map(|v| TensorRecord {
                shape: v.dims().to_vec(),
                data: v.clone().try_to_vec_as::<bool>().expect("readable tensor"),
            }),
        }
    }

    /// Rebuilds a carry on `device` (shapes are checked by the next forward).
    pub fn from_record(r: &CarryRecord, device: &Device) -> Result<Self> {
        Ok(Carry {
            slots: r
                .slots
                .as_ref()
                .map(|t| float_tensor(t, device))
                .transpose()?,
            ssm: r
                .ssm
                .as_ref()
                .map(|blocks| -> Result<SlotSsmState> {
                    Ok(SlotSsmState {
                        blocks: blocks
                            .iter()
                            .map(|(h, c)| {
                                Ok(crate::mamba::MambaState {
                                    h: float_tensor(h, device)?,
                                    conv: float_tensor(c, device)?,
                                })
                            })
                            .collect::<Result<_>>()?,
                    })
                })
                .transpose()?,
            history: r
                .history
                .as_ref()
                .map(|t| float_tensor(t, device))
                .transpose()?,
            history_valid: r
                .history_valid
                .as_ref()
                .map(|v| -> Result<Tensor<2, Bool>> {
                    let shape: [usize; 2] = v.shape.as_slice().try_into().map_err(|_| {
                        ModelError::Input("carried history validity is not 2-D".into())
                    })?;
                    Ok(Tensor::from_data(
                        TensorData::new(v.data.clone(), shape),
                        device,
                    ))
                })
                .transpose()?,
            fresh: None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seq(shape: [usize; 3], device: &Device) -> Tensor<3> {
        let n: usize = shape.iter().product();
        let values: Vec<f32> = (0..n).map(|i| i as f32).collect();
        Tensor::<1>::from_floats(values.as_slice(), device).reshape(shape)
    }

    #[test]
    fn lane_groups_split_and_join_back() {
        let device = Device::flex();
        // 4 lanes, K = 3 slots of width 2; SSM rows are lane-major (B·K).
        let carry = Carry {
            slots: Some(seq([4, 3, 2], &device)),
            ssm: Some(SlotSsmState {
                blocks: vec![crate::mamba::MambaState {
                    h: seq([12, 2, 5], &device),
                    conv: seq([12, 2, 3], &device),
                }],
            }),
            history: None,
            history_valid: None,
            fresh: Some(Tensor::from_data(
                TensorData::new(vec![true, false, false, true], [4]),
                &device,
            )),
        };
        let a = carry.lanes(0, 3, 4);
        let b = carry.lanes(3, 1, 4);
        assert_eq!(a.slots.as_ref().unwrap().dims(), [3, 3, 2]);
        assert_eq!(b.ssm.as_ref().unwrap().blocks[0].h.dims(), [3, 2, 5]);
        // Lane 3's SSM rows are rows 9..12 of the whole: its first value is 9 · 2 · 5.
        let first = b.ssm.as_ref().unwrap().blocks[0]
            .h
            .clone()
            .flatten::<1>(0, 2)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap()[0];
        assert_eq!(first, 90.0);
        assert_eq!(
            b.fresh
                .clone()
                .unwrap()
                .into_data()
                .try_to_vec::<bool>()
                .unwrap(),
            vec![true]
        );
        let joined = Carry::cat_lanes(vec![a, b]).unwrap();
        assert_eq!(joined.to_record(), carry.to_record());
        assert_eq!(
            joined
                .fresh
                .unwrap()
                .into_data()
                .try_to_vec::<bool>()
                .unwrap(),
            vec![true, false, false, true]
        );
        // A pool of 4 lanes: lanes 3 and 1 taken out, changed, and put back.
        let picked = carry.pick_lanes(&[3, 1], 4).unwrap();
        assert_eq!(
            picked.to_record(),
            Carry::cat_lanes(vec![carry.lanes(3, 1, 4), carry.lanes(1, 1, 4)])
                .unwrap()
                .to_record()
        );
        let changed = Carry {
            slots: picked.slots.clone().map(|t| t + 1000.0),
            ..picked.clone()
        };
        let back = carry.put_lanes(4, &[3, 1], &changed).unwrap();
        let slots = |c: &Carry| {
            c.slots
                .clone()
                .unwrap()
                .into_data()
                .try_to_vec::<f32>()
                .unwrap()
        };
        let (before, after) = (slots(&carry), slots(&back));
        for (i, (b, a)) in before.iter().zip(&after).enumerate() {
            let lane = i / 6;
            let want = if lane == 1 || lane == 3 {
                b + 1000.0
            } else {
                *b
            };
            assert_eq!(*a, want, "value {i} of lane {lane}");
        }
        assert_eq!(back.ssm.as_ref().unwrap().blocks[0].h.dims(), [12, 2, 5]);
        assert!(back.fresh.is_none());
        // Into an empty pool, the lanes not picked copy the batch's first lane.
        let first = Carry::default()
            .put_lanes(3, &[2], &carry.lanes(1, 1, 4))
            .unwrap();
        let lane1 = slots(&carry)[6..12].to_vec();
        assert_eq!(
            slots(&first),
            [lane1.clone(), lane1.clone(), lane1].concat()
        );
        // Parts that disagree on what they carry are refused.
        let bare = Carry::default();
        let err = Carry::cat_lanes(vec![carry.lanes(0, 2, 4), bare]).unwrap_err();
        assert!(
            err.to_string().contains("1 of 2 lane groups have it"),
            "{err}"
        );
    }
}
