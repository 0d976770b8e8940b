//! The training loop behind `frugal train`: data order, augmentation, optimizer steps,
//! per-epoch validation mAP, checkpoints that `--resume` continues from, the best model
//! and the training curves.
//!
//! Output folder:
//!
//! ```text
//! config.json              the full config (model + train)
//! checkpoint/              model.safetensors, optimizer.safetensors, state.json
//! best.safetensors         weights of the epoch with the best validation mAP
//! curves.csv, curves.png, curves.svg
//! ```
//!
//! Everything random is derived from `train.seed`: weight init (`tch::manual_seed`),
//! the data order of epoch `e` (ChaCha8 stream `e`) and each step's sampling and
//! augmentation (ChaCha8 and `tch::manual_seed` seeded from `(seed, step)`), so a
//! resumed run takes the same steps as an uninterrupted one.
//!
//! Over 600 lines only with its unit tests (the last 70).
use crate::config::{Config, TrainConfig};
use crate::frames::input_frame;
use crate::loss::batch_losses;
use crate::metrics::{Interpolation, Truth, evaluate};
use crate::optim::{Optimizer, learning_rate};
use crate::{FasterRcnn, ModelError, curves};
use frugal_data::{Dataset, FrameRecord, Split};
use frugal_runtime::BBox;
use indicatif::{ProgressBar, ProgressStyle};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use tch::{Device, Kind, Tensor};

pub use crate::curves::EpochRecord;
pub use crate::frames::{detect_frames, frame_truth, scenario, spread};

/// What one `frugal train` invocation is asked to do.
#[derive(Clone, Debug)]
pub struct TrainOptions {
    /// Dataset folder (`frugal_data::Dataset::load`).
    pub data: PathBuf,
    /// Output folder.
    pub out: PathBuf,
    /// The configuration (ignored in favour of the saved one when resuming, but it
    /// must then equal it).
    pub config: Config,
    /// Continue from `out/checkpoint`.
    pub resume: bool,
    /// Stop once this many epochs are complete (a deliberate interruption; the run
    /// can be resumed).
    pub stop_after: Option<usize>,
    /// Show a progress bar.
    pub progress: bool,
    /// Where to train: `Device::Cpu` (the default and tested path) or a CUDA device
    /// (see [`parse_device`]). Checkpoints are device-independent.
    pub device: Device,
}

/// Parse a device name: `cpu`, `cuda` (device 0) or `cuda:N`. A CUDA device is
/// accepted only when the linked libtorch has CUDA and sees that device, so a CPU-only
/// set-up fails here, before any work, with a message saying how to get CUDA.
pub fn parse_device(name: &str) -> Result<Device, ModelError> {
    let bad = |msg: String| ModelError::Config {
        file: "--device".into(),
        msg,
    };
    let index = match name {
        "cpu" => return Ok(Device::Cpu),
        "cuda" => 0,
        other => other
            .strip_prefix("cuda:")
            .and_then(|n| n.parse::<usize>().ok())
            .ok_or_else(|| {
                bad(format!(
                    "unknown device `{other}` (allowed: cpu, cuda, cuda:N)"
                ))
            })?,
    };
    if !tch::Cuda::is_available() {
        return Err(bad(format!(
            "`{name}` requested, but the linked libtorch has no CUDA or sees no GPU (set up a CUDA libtorch with `cargo xtask setup --cuda`)"
        )));
    }
    let count = tch::Cuda::device_count() as usize;
    if index >= count {
        return Err(bad(format!(
            "`{name}` requested, but only {count} CUDA device(s) are visible"
        )));
    }
    Ok(Device::Cuda(index))
}

/// The training state saved with every checkpoint.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainState {
    /// Completed epochs.
    pub epochs_done: usize,
    /// Optimizer steps taken.
    pub step: u64,
    /// The data-order RNG: ChaCha8 seeded with `seed`, stream = epoch index.
    pub rng_seed: u64,
    /// Best validation mAP so far.
    pub best_map: f64,
    /// Epoch that reached it.
    pub best_epoch: usize,
    /// Every completed epoch.
    pub history: Vec<EpochRecord>,
}

/// What a finished training run reports.
#[derive(Clone, Debug, Serialize)]
pub struct TrainReport {
    /// The final state.
    pub state: TrainState,
    /// Seconds spent in this invocation.
    pub seconds: f64,
}

fn mix(seed: u64, step: u64) -> u64 {
    let mut z = seed ^ step.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ModelError> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).map_err(|e| ModelError::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| ModelError::io(path, e))
}

/// The config as training uses it on `ds`: the dataset's class count, and the input size
/// fixed (the configured one, else from the first training frame's size).
fn adopt_data(config: &Config, ds: &Dataset, data: &Path) -> Result<Config, ModelError> {
    let mut c = config.clone();
    c.model.num_classes = ds.classes.len();
    if c.model.input_size.is_none() {
        let first = ds.split(Split::Train).next().ok_or_else(|| {
            ModelError::Data(format!("{}: the train split is empty", data.display()))
        })?;
        let (h, w) = c
            .model
            .input_for(first.width as usize, first.height as usize);
        c.model.input_size = Some([w, h]);
    }
    Ok(c)
}

/// Photometric augmentation of a `[1, 3, H, W]` image in `[0, 1]`: brightness, an
/// optional 3×3 Gaussian blur, Gaussian noise. No flips (left/right arrows).
pub fn augment(img: &Tensor, tc: &TrainConfig, rng: &mut ChaCha8Rng) -> Tensor {
    let b = tc.brightness.clamp(0.0, 0.95);
    let factor = if b > 0.0 {
        rng.random_range(1.0 - b..=1.0 + b)
    } else {
        1.0
    };
    let mut x = img * f64::from(factor);
    if tc.blur_prob > 0.0 && rng.random_bool(tc.blur_prob.clamp(0.0, 1.0)) {
        let k = Tensor::from_slice(&[1.0f32, 2.0, 1.0, 2.0, 4.0, 2.0, 1.0, 2.0, 1.0]) / 16.0;
        let k = k
            .reshape([1, 1, 3, 3])
            .repeat([3, 1, 1, 1])
            .to_device(img.device());
        x = x.conv2d::<Tensor>(&k, None, [1, 1], [1, 1], [1, 1], 3);
    }
    if tc.noise > 0.0 {
        let sigma = rng.random_range(0.0..=tc.noise);
        x = &x + x.randn_like() * f64::from(sigma);
    }
    x.clamp(0.0, 1.0)
}

/// Geometric augmentation: zoom by a factor in `[1/(1+z), 1+z]` (`z = scale_jitter`)
/// about a random point, cropping or padding (grey) back to the original size; boxes
/// follow, and objects left less than half visible are dropped. Per-channel colour
/// gains in `[1 − g, 1 + g]` (`g = channel_gain`) are applied too. No flips.
pub fn augment_geometry(
    img: &Tensor,
    truth: &[Truth],
    tc: &TrainConfig,
    rng: &mut ChaCha8Rng,
) -> (Tensor, Vec<Truth>) {
    let (_, _, h, w) = img.size4().unwrap_or((1, 3, 1, 1));
    let mut x = img.shallow_clone();
    if tc.channel_gain > 0.0 {
        let g = tc.channel_gain.clamp(0.0, 0.9);
        let gains: Vec<f32> = (0..3)
            .map(|_| rng.random_range(1.0 - g..=1.0 + g))
            .collect();
        // not `*=`: `x` shares its storage with `img`, which must stay untouched
        let gains = Tensor::from_slice(&gains)
            .reshape([1, 3, 1, 1])
            .to_device(img.device());
        x = x.multiply(&gains);
    }
    if tc.scale_jitter <= 0.0 {
        return (x, truth.to_vec());
    }
    let z = 1.0 + tc.scale_jitter;
    let s = rng.random_range(1.0 / z..=z);
    let (nh, nw) = (
        ((h as f32) * s).round().max(1.0) as i64,
        ((w as f32) * s).round().max(1.0) as i64,
    );
    let scaled = x.upsample_bilinear2d([nh, nw], false, None, None);
    let (sx, sy) = (nw as f32 / w as f32, nh as f32 / h as f32);
    // offset of the scaled image inside the canvas (negative = cropped)
    let ox = if nw >= w {
        -rng.random_range(0..=nw - w)
    } else {
        rng.random_range(0..=w - nw)
    };
    let oy = if nh >= h {
        -rng.random_range(0..=nh - h)
    } else {
        rng.random_range(0..=h - nh)
    };
    let canvas = if nw >= w && nh >= h {
        scaled.narrow(3, -ox, w).narrow(2, -oy, h)
    } else {
        let mut c = Tensor::full([1, 3, h, w], 0.5, (Kind::Float, img.device()));
        let (src_x, dst_x, len_x) = if ox < 0 { (-ox, 0, w) } else { (0, ox, nw) };
        let (src_y, dst_y, len_y) = if oy < 0 { (-oy, 0, h) } else { (0, oy, nh) };
        c.narrow(3, dst_x, len_x)
            .narrow(2, dst_y, len_y)
            .copy_(&scaled.narrow(3, src_x, len_x).narrow(2, src_y, len_y));
        let _ = &mut c;
        c
    };
    let boxes = truth
        .iter()
        .filter_map(|t| {
            let b = BBox::new(
                t.bbox.x1 * sx + ox as f32,
                t.bbox.y1 * sy + oy as f32,
                t.bbox.x2 * sx + ox as f32,
                t.bbox.y2 * sy + oy as f32,
            );
            let c = b.clip(w as f32, h as f32);
            (c.area() >= 0.5 * b.area() && c.width() >= 4.0 && c.height() >= 4.0).then_some(Truth {
                class: t.class,
                bbox: c,
            })
        })
        .collect();
    (canvas, boxes)
}

/// `[B, 3, H, W]` in `[0, 1]` → normalised with the model's mean / std.
fn normalise(model: &FasterRcnn, x: &Tensor) -> Tensor {
    let c = model.config();
    let mean = Tensor::from_slice(&c.pixel_mean)
        .reshape([1, 3, 1, 1])
        .to_device(x.device());
    let std = Tensor::from_slice(&c.pixel_std)
        .reshape([1, 3, 1, 1])
        .to_device(x.device());
    (x - mean) / std
}

/// One epoch's frame order: as many draws as there are frames, frame `i` about
/// `weights[i]` times as often as a frame of weight 1 (each frame `⌊w⌋` times, plus once
/// more with probability `w − ⌊w⌋`, shuffled, then cut to length). All weights 1 give a
/// plain shuffle of every frame.
pub fn epoch_order(weights: &[f64], rng: &mut ChaCha8Rng) -> Vec<usize> {
    let mut pool: Vec<usize> = Vec::with_capacity(weights.len());
    for (i, &w) in weights.iter().enumerate() {
        let w = w.max(0.0);
        let whole = w.floor();
        for _ in 0..whole as usize {
            pool.push(i);
        }
        if w > whole && rng.random::<f64>() < w - whole {
            pool.push(i);
        }
    }
    pool.shuffle(rng);
    pool.truncate(weights.len());
    pool
}

struct Paths {
    config: PathBuf,
    ckpt: PathBuf,
    best: PathBuf,
}

impl Paths {
    fn new(out: &Path) -> Self {
        Self {
            config: out.join("config.json"),
            ckpt: out.join("checkpoint"),
            best: out.join("best.safetensors"),
        }
    }
}

fn save_checkpoint(
    dir: &Path,
    model: &FasterRcnn,
    opt: &Optimizer,
    state: &TrainState,
) -> Result<(), ModelError> {
    let tmp = dir.with_file_name("checkpoint.tmp");
    let old = dir.with_file_name("checkpoint.old");
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| ModelError::io(&tmp, e))?;
    }
    std::fs::create_dir_all(&tmp).map_err(|e| ModelError::io(&tmp, e))?;
    model.save(&tmp.join("model.safetensors"))?;
    opt.save(&tmp.join("optimizer.safetensors"))?;
    let json = serde_json::to_vec_pretty(state).map_err(|e| ModelError::Data(e.to_string()))?;
    write_atomic(&tmp.join("state.json"), &json)?;
    if dir.exists() {
        if old.exists() {
            std::fs::remove_dir_all(&old).map_err(|e| ModelError::io(&old, e))?;
        }
        std::fs::rename(dir, &old).map_err(|e| ModelError::io(dir, e))?;
    }
    std::fs::rename(&tmp, dir).map_err(|e| ModelError::io(dir, e))?;
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(|e| ModelError::io(&old, e))?;
    }
    Ok(())
}

fn load_checkpoint(
    dir: &Path,
    model: &mut FasterRcnn,
    opt: &mut Optimizer,
) -> Result<TrainState, ModelError> {
    // a crash between the two renames leaves only checkpoint.old
    let old = dir.with_file_name("checkpoint.old");
    let dir = if dir.exists() { dir.to_path_buf() } else { old };
    let state_path = dir.join("state.json");
    let text = std::fs::read_to_string(&state_path).map_err(|e| ModelError::io(&state_path, e))?;
    let state: TrainState = serde_json::from_str(&text).map_err(|e| ModelError::Checkpoint {
        file: state_path.display().to_string(),
        msg: e.to_string(),
    })?;
    model.load_weights(&dir.join("model.safetensors"))?;
    opt.load(&dir.join("optimizer.safetensors"))?;
    Ok(state)
}

/// Train (or resume training) a detector; see the module docs for the outputs.
pub fn train(opts: &TrainOptions) -> Result<TrainReport, ModelError> {
    let t0 = std::time::Instant::now();
    let paths = Paths::new(&opts.out);
    let ds = Dataset::load(&opts.data).map_err(|e| ModelError::Data(e.to_string()))?;
    let given = adopt_data(&opts.config, &ds, &opts.data)?;
    let config = if opts.resume {
        let saved = Config::load(&paths.config)?;
        // only `train.epochs` may change on resume (to extend a finished run; the
        // learning-rate schedule is then recomputed over the new total)
        let mut same = given.clone();
        same.train.epochs = saved.train.epochs;
        if same != saved || given.train.epochs < saved.train.epochs {
            return Err(ModelError::Config {
                file: paths.config.display().to_string(),
                msg: "the given config differs from the one this run was started with (omit --config to resume; only a larger train.epochs may change)".into(),
            });
        }
        if given.train.epochs != saved.train.epochs {
            let json =
                serde_json::to_vec_pretty(&given).map_err(|e| ModelError::Data(e.to_string()))?;
            write_atomic(&paths.config, &json)?;
        }
        given.clone()
    } else {
        given.clone()
    };
    config.validate("config")?;
    let tc = config.train.clone();
    if tc.threads > 0 {
        tch::set_num_threads(tc.threads as i32);
    }
    let input = config.model.input_for(0, 0);
    let train_frames: Vec<&FrameRecord> = spread(ds.split(Split::Train).collect(), tc.train_frames);
    if train_frames.is_empty() {
        return Err(ModelError::Data(format!(
            "{}: the train split is empty",
            opts.data.display()
        )));
    }
    let val_frames = spread(ds.split(Split::Val).collect(), tc.val_frames);
    let weights: Vec<f64> = train_frames
        .iter()
        .map(|f| {
            let name = scenario(&ds, f);
            tc.scenario_weights.get(&name).copied().unwrap_or(1.0)
        })
        .collect();
    if weights.iter().all(|&w| w <= 0.0) {
        return Err(ModelError::Data(format!(
            "{}: scenario_weights give every training frame weight 0",
            opts.data.display()
        )));
    }
    if let Some(f) = train_frames
        .iter()
        .flat_map(|f| &f.objects)
        .find(|o| usize::from(o.class) >= config.model.num_classes)
    {
        return Err(ModelError::Data(format!(
            "{}: class {} is outside the model's {} classes",
            opts.data.display(),
            f.class,
            config.model.num_classes
        )));
    }

    tch::manual_seed(tc.seed as i64);
    let mut model = FasterRcnn::new(config.model.clone(), opts.device)?;
    let mut opt = Optimizer::new(model.var_store(), &tc);
    std::fs::create_dir_all(&opts.out).map_err(|e| ModelError::io(&opts.out, e))?;
    let mut state = if opts.resume {
        load_checkpoint(&paths.ckpt, &mut model, &mut opt)?
    } else {
        let json =
            serde_json::to_vec_pretty(&config).map_err(|e| ModelError::Data(e.to_string()))?;
        write_atomic(&paths.config, &json)?;
        TrainState {
            epochs_done: 0,
            step: 0,
            rng_seed: tc.seed,
            best_map: -1.0,
            best_epoch: 0,
            history: Vec::new(),
        }
    };

    let steps_per_epoch = train_frames.len().div_ceil(tc.batch_size);
    let total_steps = steps_per_epoch * tc.epochs;
    let last_epoch = opts.stop_after.unwrap_or(tc.epochs).min(tc.epochs);
    let bar = if opts.progress {
        ProgressBar::new(total_steps as u64)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] {pos}/{len} steps (eta {eta}) {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_position(state.step);

    for epoch in state.epochs_done..last_epoch {
        let te = std::time::Instant::now();
        let mut order_rng = ChaCha8Rng::seed_from_u64(state.rng_seed);
        order_rng.set_stream(epoch as u64);
        let order = epoch_order(&weights, &mut order_rng);
        let mut sums = [0.0f64; 5];
        // seconds spent on data (read, decode, augment), forward, backward + step
        let mut spent = [0.0f64; 3];
        let mut n_steps = 0usize;
        let mut lr = tc.lr;
        for batch in order.chunks(tc.batch_size) {
            let s = mix(tc.seed, state.step);
            let mut rng = ChaCha8Rng::seed_from_u64(s);
            tch::manual_seed(s as i64);
            opt.zero_grad();
            // the batch's frames, augmented, stacked into one `[B, 3, H, W]` tensor
            let tic = std::time::Instant::now();
            let mut images = Vec::with_capacity(batch.len());
            let mut truths = Vec::with_capacity(batch.len());
            for &i in batch {
                let (img, truth) = input_frame(&ds, train_frames[i], input)?;
                let (x, truth) =
                    augment_geometry(&img.to_device(opts.device), &truth, &tc, &mut rng);
                images.push(augment(&x, &tc, &mut rng));
                truths.push(truth);
            }
            let x = normalise(&model, &Tensor::cat(&images, 0));
            spent[0] += tic.elapsed().as_secs_f64();
            let tic = std::time::Instant::now();
            let l = batch_losses(&model, &x, &truths, &tc, &mut rng);
            let mut parts = [0.0f64; 5];
            for (p, t) in
                parts
                    .iter_mut()
                    .zip([&l.rpn_objectness, &l.rpn_box, &l.roi_class, &l.roi_box])
            {
                *p = t.double_value(&[]);
            }
            let total = l.total();
            spent[1] += tic.elapsed().as_secs_f64();
            parts[4] = parts[..4].iter().sum();
            let tic = std::time::Instant::now();
            total.backward();
            lr = learning_rate(&tc, state.step as usize, total_steps);
            opt.step(lr);
            spent[2] += tic.elapsed().as_secs_f64();
            state.step += 1;
            n_steps += 1;
            for (s, p) in sums.iter_mut().zip(parts) {
                *s += p;
            }
            let m = |k: usize| sums[k] / n_steps as f64;
            bar.set_message(format!(
                "epoch {}/{} loss {:.3} (obj {:.3} rpn {:.3} cls {:.3} box {:.3})",
                epoch + 1,
                tc.epochs,
                m(4),
                m(0),
                m(1),
                m(2),
                m(3)
            ));
            bar.inc(1);
            // no terminal (a log file): a plain line now and then instead of the bar
            if opts.progress && bar.is_hidden() && state.step % 50 == 0 {
                eprintln!(
                    "step {}/{total_steps} [{:.0} s] {}",
                    state.step,
                    t0.elapsed().as_secs_f64(),
                    bar.message()
                );
            }
        }
        let validate = (epoch + 1).is_multiple_of(tc.val_every) || epoch + 1 >= last_epoch;
        let tic = std::time::Instant::now();
        let val_map = if validate {
            let results = detect_frames(&model, &ds, &val_frames)?;
            Some(
                evaluate(
                    &results,
                    config.model.num_classes,
                    0.5,
                    0.5,
                    Interpolation::AllPoint,
                )
                .map,
            )
        } else {
            None
        };
        let validation_s = tic.elapsed().as_secs_f64();
        let n = n_steps.max(1) as f64;
        state.history.push(EpochRecord {
            epoch: epoch + 1,
            step: state.step,
            loss: sums[4] / n,
            rpn_objectness: sums[0] / n,
            rpn_box: sums[1] / n,
            roi_class: sums[2] / n,
            roi_box: sums[3] / n,
            val_map,
            lr,
            seconds: te.elapsed().as_secs_f64(),
            data_s: spent[0],
            forward_s: spent[1],
            backward_s: spent[2],
            validation_s,
        });
        state.epochs_done = epoch + 1;
        if let Some(val_map) = val_map.filter(|&m| m > state.best_map) {
            state.best_map = val_map;
            state.best_epoch = epoch + 1;
            model.save(&paths.best)?;
        }
        save_checkpoint(&paths.ckpt, &model, &opt, &state)?;
        curves::write(&opts.out, &state.history)?;
        bar.println(format!(
            "epoch {} done: loss {:.4}, val mAP@0.5 {}; {:.0} s: data {:.0}, forward {:.0}, backward + step {:.0}, validation {:.0}",
            epoch + 1,
            sums[4] / n,
            val_map.map_or("not validated".to_string(), |m| format!("{m:.4}")),
            te.elapsed().as_secs_f64(),
            spent[0],
            spent[1],
            spent[2],
            validation_s
        ));
    }
    bar.finish_and_clear();
    Ok(TrainReport {
        state,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epoch_order_draws_frames_by_scenario_weight() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        // all weights 1: a permutation of every frame
        let mut o = epoch_order(&[1.0; 50], &mut rng);
        assert_eq!(o.len(), 50);
        o.sort_unstable();
        assert_eq!(o, (0..50).collect::<Vec<_>>());
        // frames 0..10 weight 3, 10..20 weight 0, the rest 1: same length, the weighted
        // ones about three times as often, the zero-weight ones never
        let w: Vec<f64> = (0..60)
            .map(|i| match i {
                0..10 => 3.0,
                10..20 => 0.0,
                _ => 1.0,
            })
            .collect();
        let (mut heavy, mut light) = (0usize, 0usize);
        for _ in 0..200 {
            let o = epoch_order(&w, &mut rng);
            assert_eq!(o.len(), 60);
            assert!(o.iter().all(|&i| !(10..20).contains(&i)));
            heavy += o.iter().filter(|&&i| i < 10).count();
            light += o.iter().filter(|&&i| i >= 20).count();
        }
        // per frame: heavy / 10 vs light / 40, expect a ratio of 3
        let ratio = (heavy as f64 / 10.0) / (light as f64 / 40.0);
        assert!((ratio - 3.0).abs() < 0.2, "ratio {ratio}");
    }

    #[test]
    fn geometric_augmentation_moves_boxes_with_the_pixels() {
        let (h, w) = (64i64, 96i64);
        let img = Tensor::zeros([1, 3, h, w], (Kind::Float, Device::Cpu));
        let _ = img.narrow(2, 20, 16).narrow(3, 30, 24).fill_(1.0);
        let truth = [Truth {
            class: 4,
            bbox: BBox::new(30.0, 20.0, 54.0, 36.0),
        }];
        let tc = TrainConfig {
            scale_jitter: 0.5,
            channel_gain: 0.0,
            ..Default::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut seen = 0;
        for _ in 0..40 {
            let (x, t) = augment_geometry(&img, &truth, &tc, &mut rng);
            assert_eq!(x.size(), vec![1, 3, h, w]);
            for t in &t {
                seen += 1;
                assert_eq!(t.class, 4);
                // the inner part of the moved box is still the white square
                let b = t.bbox;
                let (x1, y1) = (b.x1.ceil() as i64 + 1, b.y1.ceil() as i64 + 1);
                let (x2, y2) = (b.x2.floor() as i64 - 1, b.y2.floor() as i64 - 1);
                if x2 > x1 && y2 > y1 {
                    let inner = x
                        .narrow(2, y1, y2 - y1)
                        .narrow(3, x1, x2 - x1)
                        .mean(Kind::Float)
                        .double_value(&[]);
                    assert!(inner > 0.95, "box {b:?} covers mean {inner}");
                }
            }
        }
        assert!(seen > 20);
    }
}
