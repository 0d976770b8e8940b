//! Compressed variants of the detector, the library side of `frugal compress`.
//!
//! A declarative grid ([`Grid`], TOML or JSON, unknown fields rejected, defaults built
//! in) lists variants, each made from a parent (the base model when none is given) by
//! one [`Technique`]:
//!
//! - **int8** ([`quant`]): post-training static quantization — symmetric per-channel
//!   int8 weights, uint8 activations calibrated on training frames (min-max,
//!   percentile or entropy), exported as an ONNX QDQ graph that ONNX Runtime fuses into
//!   integer kernels. The RPN's 1×1 output convs and the final class / box FC layers
//!   stay fp32 (see [`quant::default_quantized_layers`]).
//! - **magnitude** ([`prune::magnitude_prune`]): global magnitude pruning of conv and
//!   FC weights, fine-tuned with the masks re-applied after every step. The export is
//!   dense: ONNX Runtime's dense kernels do not skip zeros, so this buys no speed
//!   (the Pareto table shows it).
//! - **channels** ([`prune::prune_channels`]): structured pruning by filter L1 norm,
//!   physically smaller layers, fine-tuned.
//! - **drop_blocks** ([`prune::drop_blocks`]): backbone blocks removed, fine-tuned.
//! - **resolution**: a smaller fixed input (the executor resizes incoming frames and
//!   scales boxes back), fine-tuned at that size.
//!
//! **Measured** (default grid on the default model, 360 validation frames, ONNX Runtime
//! 1.31, one thread, all variants interleaved on a shared 2-core machine; medians):
//! fp32 base 26.1 ms, mAP@0.5 0.712; int8 (percentile 99.99) 13.7 ms (1.90×), mAP
//! 0.698; int8 (min-max) 13.6 ms, 0.708; 50 % channel-pruned 7.6 ms (3.4× faster than
//! its parent), 0.537 after 150 fine-tuning steps; magnitude pruning 30–90 % 26.1–26.3 ms
//! (dense kernels: no gain). The end-to-end int8 ratio is capped by `RoiAlign`, which
//! stays fp32 (the backbone graph alone runs 2.7× faster in int8). Entropy calibration
//! clipped the activations too tightly here (mAP 0.659).
//!
//! Every variant folder `<out>/<name>/` holds `backbone_rpn.onnx`, `roi_head.onnx`,
//! `variant.json` ([`VariantRecord`]: parent, technique, parameters, sizes, SHA-256)
//! and, for fp32 variants, `model/` (config + weights) from which children start.
pub mod finetune;
pub mod prune;
pub mod quant;

use crate::config::Config;
use crate::onnx::{
    BACKBONE_RPN_FILE, OrtDetector, QuantSpec, ROI_HEAD_FILE, export_detector_quantized,
};
use crate::{FasterRcnn, ModelError};
use finetune::FinetuneConfig;
use frugal_data::{Dataset, FrameRecord, Split};
use quant::Calibration;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use tch::Device;

/// How a variant is made from its parent.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Technique {
    /// The parent as it is (the base model when there is no parent).
    Base,
    /// Static int8 quantization (QDQ); `calibration` overrides the grid's method.
    Int8 {
        /// Calibration method for this variant.
        #[serde(default)]
        calibration: Option<Calibration>,
    },
    /// Global magnitude pruning to `sparsity` (fraction of conv + FC weights zeroed).
    Magnitude {
        /// Fraction in `[0, 1)`.
        sparsity: f64,
    },
    /// Structured channel pruning keeping the fraction `keep` of every layer's channels.
    Channels {
        /// Fraction in `(0, 1]`.
        keep: f64,
    },
    /// Remove these backbone blocks.
    DropBlocks {
        /// Block indices.
        blocks: Vec<usize>,
    },
    /// Proposals kept after the RPN's NMS at inference (RoIAlign and the RoI head's
    /// cost scale with it); no fine-tuning.
    Proposals {
        /// Proposals per frame (at least 1).
        count: usize,
    },
    /// Input resolution: `scale` × the dataset's frame size.
    Resolution {
        /// Fraction in `(0, 1]`.
        scale: f64,
    },
}

/// One entry of the grid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VariantSpec {
    /// Unique name (also the folder name).
    pub name: String,
    /// The variant it is made from (an earlier, non-int8 entry); none = the base model.
    #[serde(default)]
    pub parent: Option<String>,
    /// How.
    pub technique: Technique,
    /// Fine-tuning steps for this variant (overrides the grid's `finetune.steps`).
    #[serde(default)]
    pub steps: Option<usize>,
    /// Fine-tuning learning rate for this variant (overrides `finetune.lr`).
    #[serde(default)]
    pub lr: Option<f64>,
}

/// The variant grid of `frugal compress`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Grid {
    /// Fine-tuning budget of every fine-tuned variant.
    pub finetune: FinetuneConfig,
    /// Default calibration method of int8 variants.
    pub calibration: Calibration,
    /// Training frames used for calibration (spread over the split).
    pub calibration_frames: usize,
    /// Validation frames on which int8 outputs are compared with their fp32 parent.
    pub drift_frames: usize,
    /// The variants, parents before children.
    pub variants: Vec<VariantSpec>,
}

fn spec(name: &str, parent: Option<&str>, technique: Technique) -> VariantSpec {
    VariantSpec {
        name: name.into(),
        parent: parent.map(Into::into),
        technique,
        steps: None,
        lr: None,
    }
}

fn tuned(mut v: VariantSpec, steps: usize, lr: f64) -> VariantSpec {
    v.steps = Some(steps);
    v.lr = Some(lr);
    v
}

impl Default for Grid {
    fn default() -> Self {
        use Technique::*;
        let int8 = || Int8 { calibration: None };
        Self {
            finetune: FinetuneConfig::default(),
            calibration: Calibration::default(),
            calibration_frames: 24,
            drift_frames: 8,
            variants: vec![
                spec("base", None, Base),
                spec("base-int8", Some("base"), int8()),
                spec(
                    "base-int8-minmax",
                    Some("base"),
                    Int8 {
                        calibration: Some(Calibration::MinMax),
                    },
                ),
                spec(
                    "base-int8-entropy",
                    Some("base"),
                    Int8 {
                        calibration: Some(Calibration::Entropy),
                    },
                ),
                spec("mag50", None, Magnitude { sparsity: 0.5 }),
                spec("mag90", None, Magnitude { sparsity: 0.9 }),
                spec("ch75", None, Channels { keep: 0.75 }),
                tuned(spec("ch50", None, Channels { keep: 0.5 }), 150, 5e-4),
                spec("ch50-int8", Some("ch50"), int8()),
                // the RPN conv and fc1 start afresh after the block is removed
                tuned(
                    spec("drop3", None, DropBlocks { blocks: vec![3] }),
                    250,
                    1e-3,
                ),
                spec("drop3-int8", Some("drop3"), int8()),
                spec("p20", None, Proposals { count: 20 }),
                spec("p20-int8", Some("p20"), int8()),
                spec("res075", None, Resolution { scale: 0.75 }),
                spec("res050", None, Resolution { scale: 0.5 }),
                spec("res050-int8", Some("res050"), int8()),
                // the techniques combined, for the cheap end of the front: with 10
                // proposals instead of 50 the half-width detector took 19.4 ms instead
                // of 26.4 (an AVX2 core, 2026-11-28) at a mAP within one standard error;
                // int8 pays only on cores with 8-bit dot products (VNNI), so each int8
                // variant has its fp32 parent beside it
                spec("ch50-p10", Some("ch50"), Proposals { count: 10 }),
                spec("ch50-p10-int8", Some("ch50-p10"), int8()),
                spec(
                    "ch50-p10-res075",
                    Some("ch50-p10"),
                    Resolution { scale: 0.75 },
                ),
                spec("ch50-p10-res075-int8", Some("ch50-p10-res075"), int8()),
                spec("ch75-p20", Some("ch75"), Proposals { count: 20 }),
                spec("ch75-p20-int8", Some("ch75-p20"), int8()),
            ],
        }
    }
}

impl Grid {
    /// Read a `.toml` or JSON grid; missing fields take their defaults.
    pub fn load(path: &Path) -> Result<Self, ModelError> {
        let text = std::fs::read_to_string(path).map_err(|e| ModelError::io(path, e))?;
        let file = path.display().to_string();
        let bad = |msg: String| ModelError::Config {
            file: file.clone(),
            msg,
        };
        let g: Grid = if path.extension().is_some_and(|e| e == "toml") {
            toml::from_str(&text).map_err(|e| bad(e.to_string()))?
        } else {
            serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?
        };
        g.validate(&file)?;
        Ok(g)
    }

    /// Names unique and safe as folder names, parents defined earlier and not int8.
    pub fn validate(&self, file: &str) -> Result<(), ModelError> {
        let bad = |msg: String| {
            Err(ModelError::Config {
                file: file.into(),
                msg,
            })
        };
        if self.variants.is_empty() {
            return bad("the grid has no variants".into());
        }
        for (i, v) in self.variants.iter().enumerate() {
            if v.name.is_empty()
                || !v
                    .name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c))
                || v.name.starts_with('.')
            {
                return bad(format!(
                    "variants[{i}]: name `{}` must be [A-Za-z0-9-_.]",
                    v.name
                ));
            }
            if self.variants[..i].iter().any(|o| o.name == v.name) {
                return bad(format!("variants[{i}]: duplicate name `{}`", v.name));
            }
            if let Some(p) = &v.parent {
                match self.variants[..i].iter().find(|o| &o.name == p) {
                    None => {
                        return bad(format!(
                            "variants[{i}] ({}): parent `{p}` is not an earlier variant",
                            v.name
                        ));
                    }
                    Some(o) if matches!(o.technique, Technique::Int8 { .. }) => {
                        return bad(format!(
                            "variants[{i}] ({}): parent `{p}` is int8 (only fp32 variants can be parents)",
                            v.name
                        ));
                    }
                    _ => {}
                }
            }
        }
        if self.finetune.steps == 0 || self.calibration_frames == 0 {
            return bad("finetune.steps and calibration_frames must be >= 1".into());
        }
        Ok(())
    }
}

/// A file of a variant.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FileRecord {
    /// File name inside the variant folder.
    pub file: String,
    /// Size in bytes.
    pub bytes: u64,
    /// SHA-256, lower-case hex.
    pub sha256: String,
}

/// How far a quantized variant's raw outputs are from its fp32 parent's (ONNX Runtime,
/// both graphs' `backbone_rpn` outputs on validation frames).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Drift {
    /// Frames compared.
    pub frames: usize,
    /// Per output (`features`, `objectness`, `deltas`): max abs difference.
    pub max_abs_diff: HashMap<String, f64>,
    /// Per output: mean abs difference.
    pub mean_abs_diff: HashMap<String, f64>,
    /// Per output: mean abs value of the fp32 output (for scale).
    pub mean_abs_fp32: HashMap<String, f64>,
}

/// What `variant.json` records.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VariantRecord {
    /// Name.
    pub name: String,
    /// Parent variant (none = the base model folder).
    pub parent: Option<String>,
    /// The base model folder everything descends from.
    pub base_model: PathBuf,
    /// How it was made.
    pub technique: Technique,
    /// Input height of the exported graphs.
    pub input_height: usize,
    /// Input width.
    pub input_width: usize,
    /// Parameters (weights and biases).
    pub parameters: usize,
    /// Non-zero parameters.
    pub nonzero_parameters: usize,
    /// Whether the graphs are int8 QDQ.
    pub int8: bool,
    /// Calibration used (int8 only).
    pub calibration: Option<Calibration>,
    /// Quantized layers (int8 only).
    pub quantized_layers: Vec<String>,
    /// int8 vs fp32 parent (int8 only).
    pub drift: Option<Drift>,
    /// Fine-tuning steps taken (0 = none).
    pub finetune_steps: usize,
    /// Mean loss over the last fine-tuning steps.
    pub finetune_loss: Option<f64>,
    /// The ONNX files.
    pub files: Vec<FileRecord>,
    /// Seconds it took to make.
    pub seconds: f64,
}

/// File name of a variant's record.
pub const VARIANT_FILE: &str = "variant.json";

/// Read a `variant.json`.
pub fn read_record(path: &Path) -> Result<VariantRecord, ModelError> {
    let text = std::fs::read_to_string(path).map_err(|e| ModelError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| ModelError::Config {
        file: path.display().to_string(),
        msg: e.to_string(),
    })
}

fn file_record(dir: &Path, name: &str) -> Result<FileRecord, ModelError> {
    let p = dir.join(name);
    let bytes = std::fs::read(&p).map_err(|e| ModelError::io(&p, e))?;
    let sha256 = Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    Ok(FileRecord {
        file: name.into(),
        bytes: bytes.len() as u64,
        sha256,
    })
}

fn write_json<T: Serialize>(path: &Path, v: &T) -> Result<(), ModelError> {
    let json = serde_json::to_vec_pretty(v).map_err(|e| ModelError::Data(e.to_string()))?;
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, json).map_err(|e| ModelError::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| ModelError::io(path, e))
}

/// What `frugal compress` is asked to do.
#[derive(Clone, Debug)]
pub struct CompressOptions {
    /// Base model folder (`config.json` + `best.safetensors`).
    pub model: PathBuf,
    /// Dataset folder.
    pub data: PathBuf,
    /// Output folder (one sub-folder per variant).
    pub out: PathBuf,
    /// The grid.
    pub grid: Grid,
    /// Print progress lines.
    pub progress: bool,
}

fn frame_of(ds: &Dataset, f: &FrameRecord) -> Result<image::RgbImage, ModelError> {
    ds.load_rgb(f).map_err(|e| ModelError::Data(e.to_string()))
}

/// Compare the `backbone_rpn` outputs of two exports on frames.
fn drift(
    fp32: &Path,
    int8: &Path,
    ds: &Dataset,
    frames: &[&FrameRecord],
) -> Result<Drift, ModelError> {
    let ort_err = |e: crate::onnx::OrtError| ModelError::Data(e.to_string());
    let mut a = OrtDetector::open(fp32, 1).map_err(ort_err)?;
    let mut b = OrtDetector::open(int8, 1).map_err(ort_err)?;
    let (h, w) = (a.spec().height, a.spec().width);
    let names = ["features", "objectness", "deltas"];
    let mut max = HashMap::new();
    let mut sum = [0.0f64; 3];
    let mut abs = [0.0f64; 3];
    let mut count = [0usize; 3];
    for f in frames {
        let rgb = frame_of(ds, f)?;
        let frame = frugal_runtime::FrameRef::new(rgb.width(), rgb.height(), rgb.as_raw())
            .ok_or_else(|| ModelError::Data(format!("{}: bad frame", f.file.display())))?;
        let px = crate::onnx::executor::resize_bilinear(frame, w as u32, h as u32);
        let fr = frugal_runtime::FrameRef::new(w as u32, h as u32, &px)
            .ok_or_else(|| ModelError::Data("resize".into()))?;
        let img = crate::glue::normalize(fr, a.spec().pixel_mean, a.spec().pixel_std);
        let oa = a.run_backbone(img.clone()).map_err(ort_err)?;
        let ob = b.run_backbone(img).map_err(ort_err)?;
        for (k, (x, y)) in [(&oa.0, &ob.0), (&oa.1, &ob.1), (&oa.2, &ob.2)]
            .into_iter()
            .enumerate()
        {
            for (u, v) in x.iter().zip(y.iter()) {
                let d = f64::from((u - v).abs());
                let m = max.entry(names[k].to_string()).or_insert(0.0f64);
                *m = m.max(d);
                sum[k] += d;
                abs[k] += f64::from(u.abs());
                count[k] += 1;
            }
        }
    }
    let per = |v: [f64; 3]| {
        names
            .iter()
            .enumerate()
            .map(|(k, n)| (n.to_string(), v[k] / count[k].max(1) as f64))
            .collect()
    };
    Ok(Drift {
        frames: frames.len(),
        max_abs_diff: max,
        mean_abs_diff: per(sum),
        mean_abs_fp32: per(abs),
    })
}

/// Make every variant of the grid; returns their records (also written to
/// `<out>/<name>/variant.json`).
pub fn compress(opts: &CompressOptions) -> Result<Vec<VariantRecord>, ModelError> {
    let grid = &opts.grid;
    grid.validate("compress grid")?;
    let base_cfg = Config::load(&opts.model.join("config.json"))?;
    if base_cfg.train.threads > 0 {
        tch::set_num_threads(base_cfg.train.threads as i32);
    }
    let ds = Dataset::load(&opts.data).map_err(|e| ModelError::Data(e.to_string()))?;
    let first = ds.split(Split::Train).next().ok_or_else(|| {
        ModelError::Data(format!("{}: the train split is empty", opts.data.display()))
    })?;
    // the base model's input size (trained on these frames), else the frames' own
    // (the saved config, not the weights: the loop below loads the model itself)
    let full = crate::config::Config::load(&opts.model.join("config.json"))?
        .model
        .input_size
        .map_or((first.height as usize, first.width as usize), |[w, h]| {
            (h, w)
        });
    let calib_frames =
        crate::frames::spread(ds.split(Split::Train).collect(), grid.calibration_frames);
    let drift_frames = crate::frames::spread(ds.split(Split::Val).collect(), grid.drift_frames);
    std::fs::create_dir_all(&opts.out).map_err(|e| ModelError::io(&opts.out, e))?;
    // name → (fp32 model folder, input size)
    let mut made: HashMap<String, (PathBuf, (usize, usize))> = HashMap::new();
    let mut records = Vec::new();
    for v in &grid.variants {
        let t0 = std::time::Instant::now();
        if opts.progress {
            eprintln!("compress: {} ({:?})", v.name, v.technique);
        }
        let (parent_dir, mut input) = match &v.parent {
            Some(p) => made[p].clone(),
            None => (opts.model.clone(), full),
        };
        let mut model = FasterRcnn::load_dir(&parent_dir, Device::Cpu)?;
        let dir = opts.out.join(&v.name);
        std::fs::create_dir_all(&dir).map_err(|e| ModelError::io(&dir, e))?;
        let mut masks = None;
        let mut tune = true;
        let mut quant: Option<(QuantSpec, Calibration)> = None;
        match &v.technique {
            Technique::Base => tune = false,
            Technique::Int8 { calibration } => {
                tune = false;
                let method = calibration.unwrap_or(grid.calibration);
                let imgs = calib_frames
                    .iter()
                    .map(|f| finetune::model_input(&model, &ds, f, input))
                    .collect::<Result<Vec<_>, _>>()?;
                let stats = quant::collect_stats(&model, &imgs)?;
                let layers = quant::default_quantized_layers(&model);
                quant = Some((quant::quant_spec(&stats, method, &layers), method));
            }
            Technique::Magnitude { sparsity } => {
                masks = Some(prune::magnitude_prune(&model, *sparsity)?);
            }
            Technique::Channels { keep } => model = prune::prune_channels(&model, *keep)?.0,
            Technique::DropBlocks { blocks } => model = prune::drop_blocks(&model, blocks)?,
            Technique::Proposals { count } => {
                tune = false;
                let mut cfg = model.config().clone();
                cfg.post_nms_test = *count;
                cfg.pre_nms_test = cfg.pre_nms_test.max(*count);
                model = prune::with_config(&model, cfg)?;
            }
            Technique::Resolution { scale } => {
                if !(*scale > 0.0 && *scale <= 1.0) {
                    return Err(ModelError::Config {
                        file: "compress grid".into(),
                        msg: format!("{}: resolution scale must be in (0, 1]", v.name),
                    });
                }
                input = (
                    ((full.0 as f64 * scale).round() as usize).max(16),
                    ((full.1 as f64 * scale).round() as usize).max(16),
                );
            }
        }
        let mut loss = None;
        if tune {
            let ft = FinetuneConfig {
                steps: v.steps.unwrap_or(grid.finetune.steps),
                lr: v.lr.unwrap_or(grid.finetune.lr),
                ..grid.finetune.clone()
            };
            let steps = ft.steps;
            let progress = opts.progress;
            let name = v.name.clone();
            loss = Some(finetune::finetune(
                &model,
                &ds,
                &base_cfg.train,
                &ft,
                input,
                masks.as_ref(),
                |s, l| {
                    if progress && (s % 20 == 0 || s == steps) {
                        eprintln!("  {name}: fine-tune step {s}/{steps} loss {l:.3}");
                    }
                },
            )?);
        }
        export_detector_quantized(&model, input.0, input.1, quant.as_ref().map(|q| &q.0), &dir)?;
        if quant.is_none() {
            let mdir = dir.join("model");
            std::fs::create_dir_all(&mdir).map_err(|e| ModelError::io(&mdir, e))?;
            let cfg = Config {
                model: model.config().clone(),
                train: base_cfg.train.clone(),
            };
            write_json(&mdir.join("config.json"), &cfg)?;
            model.save(&mdir.join("best.safetensors"))?;
            made.insert(v.name.clone(), (mdir, input));
        }
        let drift = match (&quant, &v.parent) {
            (Some(_), Some(p)) => Some(drift(&opts.out.join(p), &dir, &ds, &drift_frames)?),
            _ => None,
        };
        let params = prune::parameter_count(&model);
        let zeros: usize = model
            .var_store()
            .variables()
            .values()
            .map(|t| t.eq(0.0).sum(tch::Kind::Int64).int64_value(&[]) as usize)
            .sum();
        let rec = VariantRecord {
            name: v.name.clone(),
            parent: v.parent.clone(),
            base_model: opts.model.clone(),
            technique: v.technique.clone(),
            input_height: input.0,
            input_width: input.1,
            parameters: params,
            nonzero_parameters: params - zeros,
            int8: quant.is_some(),
            calibration: quant.as_ref().map(|q| q.1),
            quantized_layers: quant
                .as_ref()
                .map(|q| q.0.layers.iter().cloned().collect())
                .unwrap_or_default(),
            drift,
            finetune_steps: if tune {
                v.steps.unwrap_or(grid.finetune.steps)
            } else {
                0
            },
            finetune_loss: loss,
            files: vec![
                file_record(&dir, BACKBONE_RPN_FILE)?,
                file_record(&dir, ROI_HEAD_FILE)?,
            ],
            seconds: t0.elapsed().as_secs_f64(),
        };
        write_json(&dir.join(VARIANT_FILE), &rec)?;
        if opts.progress {
            eprintln!(
                "  {}: {} params, {}×{} input, {:.0} s",
                rec.name, rec.parameters, rec.input_width, rec.input_height, rec.seconds
            );
        }
        records.push(rec);
    }
    Ok(records)
}

#[cfg(test)]
mod tests;
