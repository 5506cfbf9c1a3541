//! Burn adapters (feature `burn`): [`WindowDataset`] as a Burn `Dataset` and a `Batcher` that
//! stacks [`WindowSample`]s into tensors.

use burn::data::dataloader::batcher::Batcher;
use burn::data::dataset::{Dataset, DatasetError};
use burn::tensor::{Bool, Device, Int, Tensor, TensorData};

use crate::text::Vocab;
use crate::window::{WindowDataset, WindowSample};

impl Dataset<WindowSample> for WindowDataset {
    fn get(&self, index: usize) -> Result<WindowSample, DatasetError> {
        WindowDataset::get(self, index).map_err(DatasetError::new)
    }

    fn len(&self) -> usize {
        WindowDataset::len(self)
    }
}

/// A batch of windows on a device.
#[derive(Clone, Debug)]
pub struct WindowBatch {
    /// Agentview frames `[B, T, 3, H, W]` in [0, 1].
    pub images: Tensor<5>,
    /// Eye-in-hand frames `[B, T, 3, H, W]` when the dataset produces them.
    pub wrist_images: Option<Tensor<5>>,
    /// `[B, T]`: real (true) vs repeated edge frame (false).
    pub frame_mask: Tensor<2, Bool>,
    /// Normalised action chunks `[B, T, H_a, 7]`.
    pub actions: Tensor<4>,
    /// `[B, T, H_a]`: real action (true) vs repeated past the episode end (false).
    pub action_mask: Tensor<3, Bool>,
    /// States `[B, T, 8]`.
    pub states: Tensor<3>,
    /// Instruction token ids `[B, L]` (0 = pad).
    pub instruction_ids: Tensor<2, Int>,
    /// `[B, L]`: real token.
    pub instruction_mask: Tensor<2, Bool>,
    /// Current-subgoal token ids `[B, T, L]`.
    pub subgoal_ids: Tensor<3, Int>,
    /// `[B, T, L]`: real token.
    pub subgoal_mask: Tensor<3, Bool>,
    /// Object boxes `[B, T, N, 4]` (x, y, w, h normalised; zeros for padding).
    pub boxes: Tensor<4>,
    /// `[B, T, N]`: object present and visible.
    pub object_mask: Tensor<3, Bool>,
}

/// Stacks [`WindowSample`]s into a [`WindowBatch`]; text is tokenised with a [`Vocab`].
#[derive(Clone, Debug)]
pub struct WindowBatcher {
    /// Vocabulary (usually from `index.json`).
    pub vocab: Vocab,
    /// Text length L (tokens beyond are cut, shorter texts padded).
    pub max_text_len: usize,
    /// Objects per frame N (extra objects are dropped, missing ones padded).
    pub max_objects: usize,
}

impl WindowBatcher {
    /// A batcher with the given vocabulary and sizes.
    pub fn new(vocab: Vocab, max_text_len: usize, max_objects: usize) -> Self {
        WindowBatcher {
            vocab,
            max_text_len,
            max_objects,
        }
    }
}

impl Batcher<WindowSample, WindowBatch> for WindowBatcher {
    /// # Panics
    /// If `items` is empty or the samples come from differently configured datasets.
    fn batch(&self, items: Vec<WindowSample>, device: &Device) -> WindowBatch {
        assert!(!items.is_empty(), "cannot batch zero samples");
        let b = items.len();
        let t = items[0].frame_mask.len();
        let ha = items[0].action_mask.len() / t;
        let side = ((items[0].images.len() / (t * 3)) as f64).sqrt() as usize;
        let (l, n) = (self.max_text_len, self.max_objects);
        for it in &items {
            assert_eq!(
                it.frame_mask.len(),
                t,
                "all samples need the same window length"
            );
            assert_eq!(
                it.images.len(),
                t * 3 * side * side,
                "all samples need the same image size"
            );
            assert_eq!(
                it.actions.len(),
                t * ha * 7,
                "all samples need the same chunk length"
            );
        }
        let float = |v: Vec<f32>, shape: Vec<usize>| TensorData::new(v, shape);
        let images: Vec<f32> = items
            .iter()
            .flat_map(|s| s.images.iter().copied())
            .collect();
        let wrist = items[0].wrist_images.is_some().then(|| {
            let v: Vec<f32> = items
                .iter()
                .flat_map(|s| s.wrist_images.as_deref().unwrap_or(&[]).iter().copied())
                .collect();
            Tensor::<5>::from_data(float(v, vec![b, t, 3, side, side]), device)
        });
        let mut ins_ids = Vec::with_capacity(b * l);
        let mut ins_mask = Vec::with_capacity(b * l);
        let mut sub_ids = Vec::with_capacity(b * t * l);
        let mut sub_mask = Vec::with_capacity(b * t * l);
        let mut boxes = vec![0f32; b * t * n * 4];
        let mut obj_mask = vec![false; b * t * n];
        for (i, s) in items.iter().enumerate() {
            let (ids, m) = self.vocab.encode(&s.instruction, l);
            ins_ids.extend(ids.into_iter().map(i64::from));
            ins_mask.extend(m);
            for (j, g) in s.subgoals.iter().enumerate() {
                let (ids, m) = self.vocab.encode(g, l);
                sub_ids.extend(ids.into_iter().map(i64::from));
                sub_mask.extend(m);
                for (k, o) in s.objects[j].iter().take(n).enumerate() {
                    let at = (i * t + j) * n + k;
                    boxes[at * 4..at * 4 + 4].copy_from_slice(&o.bbox);
                    obj_mask[at] = o.visible;
                }
            }
        }
        WindowBatch {
            images: Tensor::from_data(float(images, vec![b, t, 3, side, side]), device),
            wrist_images: wrist,
            frame_mask: Tensor::from_data(
                TensorData::new(
                    items
                        .iter()
                        .flat_map(|s| s.frame_mask.iter().copied())
                        .collect::<Vec<bool>>(),
                    [b, t],
                ),
                device,
            ),
            actions: Tensor::from_data(
                float(
                    items
                        .iter()
                        .flat_map(|s| s.actions.iter().copied())
                        .collect(),
                    vec![b, t, ha, 7],
                ),
                device,
            ),
            action_mask: Tensor::from_data(
                TensorData::new(
                    items
                        .iter()
                        .flat_map(|s| s.action_mask.iter().copied())
                        .collect::<Vec<bool>>(),
                    [b, t, ha],
                ),
                device,
            ),
            states: Tensor::from_data(
                float(
                    items
                        .iter()
                        .flat_map(|s| s.states.iter().copied())
                        .collect(),
                    vec![b, t, 8],
                ),
                device,
            ),
            instruction_ids: Tensor::from_data(TensorData::new(ins_ids, [b, l]), device),
            instruction_mask: Tensor::from_data(TensorData::new(ins_mask, [b, l]), device),
            subgoal_ids: Tensor::from_data(TensorData::new(sub_ids, [b, t, l]), device),
            subgoal_mask: Tensor::from_data(TensorData::new(sub_mask, [b, t, l]), device),
            boxes: Tensor::from_data(TensorData::new(boxes, [b, t, n, 4]), device),
            object_mask: Tensor::from_data(TensorData::new(obj_mask, [b, t, n]), device),
        }
    }
}
