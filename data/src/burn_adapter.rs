//! Burn adapter (feature `burn`): [`WindowDataset`] as a Burn `Dataset`. Samples become tensors
//! in `model::io::Processor::batch`, the one batcher of training and evaluation.

use burn::data::dataset::{Dataset, DatasetError};

use crate::window::{WindowDataset, WindowSample};

impl Dataset<WindowSample> for WindowDataset {
    fn get(&self, index: usize) -> Result<WindowSample, DatasetError> {
        WindowDataset::get(self, index).map_err(DatasetError::new)
    }

    fn len(&self) -> usize {
        WindowDataset::len(self)
    }
}
