//! Shared helpers of the integration tests: synthetic datasets and configs.

use std::path::Path;

use data::synth::{SynthOptions, synthetic_meta, synthetic_steps};
use data::{EpisodeWriter, ImageCompression, IndexOptions, WriterOptions};

/// Writes `episodes` synthetic episodes of `steps` steps (`size`² frames) with `data::synth`,
/// whose arm actions are replaced by a function of what the frames show (so they can be
/// learnt), and indexes them with one episode in four held out.
pub fn write_dataset(dir: &Path, episodes: usize, steps: usize, size: u32) {
    std::fs::create_dir_all(dir).unwrap();
    for e in 0..episodes {
        let o = SynthOptions {
            size,
            segmentation: false,
            depth: false,
        };
        let opts = WriterOptions {
            image_compression: ImageCompression::Png,
            chunk_size: 64 * 1024,
            ..WriterOptions::default()
        };
        let path = dir.join(format!("synth_{e:03}.mcap"));
        let mut w = EpisodeWriter::create(path, synthetic_meta(e as u64), opts).unwrap();
        for mut s in synthetic_steps(steps, e as u64, &o) {
            // The blue bar of the frame sits at x = 0.5 + 0.2·sin(t): actions read it.
            let t = s.step as f32 * 0.05;
            for (a, g) in s.action.iter_mut().zip([1.0, -1.0, 0.5, -0.5, 0.8, -0.8]) {
                *a = 0.9 * g * t.sin();
            }
            w.write_step(&s).unwrap();
        }
        w.finish().unwrap();
    }
    data::build_index(
        dir,
        &IndexOptions {
            val_fraction: 0.25,
            seed: 0,
        },
    )
    .unwrap();
}

/// `configs/tiny.toml` (the CI config) with its dataset directory replaced.
pub fn tiny_config(data_dir: &Path) -> train::Config {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/tiny.toml");
    let mut cfg = train::Config::load(&path).unwrap();
    cfg.data.dir = data_dir.to_path_buf();
    cfg.data.generate = None;
    cfg
}

/// Every float parameter of the final checkpoint of a run (the one `latest` names), in visiting
/// order: weights compared by content (the weight files hold random parameter ids besides).
#[allow(dead_code)] // not every test binary compares weights
pub fn final_weights(run_dir: &Path) -> Vec<Vec<f32>> {
    let latest = std::fs::read_to_string(run_dir.join("checkpoints/latest")).unwrap();
    weights_of(run_dir, latest.trim(), "model.bpk")
}

/// Every float parameter of weight file `file` in checkpoint `checkpoint` of a run.
#[allow(dead_code)]
pub fn weights_of(run_dir: &Path, checkpoint: &str, file: &str) -> Vec<Vec<f32>> {
    use burn::module::{Module, ModuleVisitor, Param};
    use burn::prelude::*;
    struct Collect(Vec<Vec<f32>>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            self.0
                .push(p.val().into_data().try_to_vec::<f32>().unwrap());
        }
    }
    let cfg: model::ModelConfig =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("model.json")).unwrap())
            .unwrap();
    let path = run_dir.join("checkpoints").join(checkpoint).join(file);
    let model = model::PolicyModel::load(&cfg, path, &Device::flex()).unwrap();
    let mut c = Collect(vec![]);
    model.visit(&mut c);
    c.0
}

/// The bit patterns of [`final_weights`]' floats (equal bits: equal weights, NaN included).
#[allow(dead_code)]
pub fn bits(w: &[Vec<f32>]) -> Vec<Vec<u32>> {
    w.iter()
        .map(|t| t.iter().map(|x| x.to_bits()).collect())
        .collect()
}
