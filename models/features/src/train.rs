//! Training the family: one-vs-rest linear SVMs per HoG configuration, on ground-truth
//! windows, jittered proposals and background proposals, with hard-negative mining.
//!
//! Proposals are computed once per frame and shared by every HoG configuration; each
//! configuration then
//!
//! 1. extracts the HoG of every positive (ground-truth boxes, and proposals overlapping
//!    one at IoU ≥ `pos_iou`) and of an evenly spread subset of the background
//!    proposals (IoU < `neg_iou` with every sign);
//! 2. trains one SVM per class, the other classes' positives being its negatives too;
//! 3. `mining_rounds` times: scores every background proposal of every frame, adds the
//!    `hard_per_frame` highest-scoring ones whose best margin exceeds −1 (those that
//!    violate the margin), and retrains.

use crate::edgeboxes::EdgeBoxesConfig;
use crate::error::{Error, Result};
use crate::frame::Rgb;
use crate::hog::hog_into;
use crate::model::{Buffers, FeatureModel, HogSvms, MODEL_FORMAT, ScoreThresholds, best_class};
use crate::params::HogParams;
use crate::svm::{SvmConfig, train as train_svm};
use frugal_runtime::{BBox, ClassId};
use rayon::prelude::*;

/// A frame with its pixels and labelled boxes.
#[derive(Clone, Debug, PartialEq)]
pub struct LabeledFrame {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width * height * 3` bytes of RGB8.
    pub rgb: Vec<u8>,
    /// The signs: class and box.
    pub objects: Vec<(ClassId, BBox)>,
}

impl LabeledFrame {
    /// A checked view of the pixels.
    pub fn view(&self) -> Result<Rgb<'_>> {
        Rgb::new(self.width, self.height, &self.rgb)
    }
}

/// Training settings.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrainConfig {
    /// Side of the square reference window (see [`HogParams::geometry`]).
    pub window: usize,
    /// Proposal settings (also stored in the model for detection).
    pub edgeboxes: EdgeBoxesConfig,
    /// Split HoG votes between orientation bins.
    pub orientation_interpolation: bool,
    /// SVM solver settings.
    pub svm: SvmConfig,
    /// Proposals per training frame to draw positives and negatives from.
    pub proposals: usize,
    /// A proposal is a positive of a sign's class at this IoU or more.
    pub pos_iou: f32,
    /// A proposal is background below this IoU with every sign.
    pub neg_iou: f32,
    /// At most this many proposal positives per sign (besides its own box).
    pub jitter_per_object: usize,
    /// Background proposals per frame in the first training round.
    pub negatives_per_frame: usize,
    /// Hard-negative mining rounds.
    pub mining_rounds: usize,
    /// Hard negatives added per frame and round.
    pub hard_per_frame: usize,
    /// Confidence thresholds stored in the model.
    pub thresholds: ScoreThresholds,
    /// NMS IoU stored in the model.
    pub nms_iou: f32,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            window: 48,
            edgeboxes: EdgeBoxesConfig::default(),
            orientation_interpolation: false,
            svm: SvmConfig::default(),
            proposals: 1000,
            pos_iou: 0.7,
            neg_iou: 0.3,
            jitter_per_object: 4,
            negatives_per_frame: 10,
            mining_rounds: 1,
            hard_per_frame: 10,
            thresholds: ScoreThresholds::PAPER,
            nms_iou: 0.3,
        }
    }
}

/// Progress of a training run, reported to the caller's callback.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Progress {
    /// Proposals computed for `done` of `total` frames.
    Proposals {
        /// Frames done.
        done: usize,
        /// Frames in all.
        total: usize,
    },
    /// HoG configuration `done` of `total` finished.
    Hog {
        /// Configurations done.
        done: usize,
        /// Configurations in all.
        total: usize,
    },
}

/// Per-frame training boxes.
struct Plan {
    positives: Vec<(ClassId, BBox)>,
    negatives: Vec<BBox>,
    pool: Vec<BBox>,
}

fn plan(frame: &LabeledFrame, cfg: &TrainConfig) -> Result<Plan> {
    let img = frame.view()?;
    let props = crate::edgeboxes::proposals(&img, &cfg.edgeboxes, cfg.proposals)?;
    let mut positives: Vec<(ClassId, BBox)> = frame.objects.clone();
    let mut jitter = vec![0usize; frame.objects.len()];
    let mut pool = Vec::new();
    for p in &props {
        let best = frame
            .objects
            .iter()
            .enumerate()
            .map(|(i, (_, b))| (i, p.bbox.iou(b)))
            .max_by(|a, b| a.1.total_cmp(&b.1));
        match best {
            Some((i, iou)) if iou >= cfg.pos_iou => {
                if jitter[i] < cfg.jitter_per_object {
                    jitter[i] += 1;
                    positives.push((frame.objects[i].0, p.bbox));
                }
            }
            Some((_, iou)) if iou >= cfg.neg_iou => {}
            _ => pool.push(p.bbox),
        }
    }
    let k = cfg.negatives_per_frame.min(pool.len());
    let negatives = (0..k).map(|i| pool[i * pool.len() / k]).collect();
    Ok(Plan {
        positives,
        negatives,
        pool,
    })
}

/// Train SVM sets for every distinct HoG configuration among `variants`.
///
/// `classes` names the class ids used in the frames' objects; an object whose class
/// is out of range is an error. `progress` is called as work completes.
pub fn train(
    frames: &[LabeledFrame],
    classes: &[String],
    variants: &[HogParams],
    cfg: &TrainConfig,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<FeatureModel> {
    cfg.edgeboxes.validate()?;
    let mut keys: Vec<(u8, u8, u8)> = variants.iter().map(HogParams::hog_key).collect();
    keys.sort_unstable();
    keys.dedup();
    for v in variants {
        v.validate(cfg.window)?;
    }
    if keys.is_empty() {
        return Err(Error::Training("no parameter tuples given".into()));
    }
    if classes.is_empty() {
        return Err(Error::Training("no classes".into()));
    }
    for (i, f) in frames.iter().enumerate() {
        if let Some((c, _)) = f.objects.iter().find(|(c, _)| *c as usize >= classes.len()) {
            return Err(Error::Training(format!(
                "frame {i} has an object of class {c}, but there are {} classes",
                classes.len()
            )));
        }
    }
    let done = std::sync::atomic::AtomicUsize::new(0);
    let plans: Vec<Plan> = frames
        .par_iter()
        .map(|f| {
            let p = plan(f, cfg);
            let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(Progress::Proposals {
                done: d,
                total: frames.len(),
            });
            p
        })
        .collect::<Result<_>>()?;
    let npos: usize = plans.iter().map(|p| p.positives.len()).sum();
    if npos == 0 {
        return Err(Error::Training(format!(
            "none of the {} frames has a sign",
            frames.len()
        )));
    }
    let mut hogs = Vec::new();
    for (k, &(block, cell, bins)) in keys.iter().enumerate() {
        let params = HogParams {
            proposals: 1,
            block,
            cell,
            bins,
        };
        hogs.push(train_hog(frames, &plans, classes.len(), params, cfg)?);
        progress(Progress::Hog {
            done: k + 1,
            total: keys.len(),
        });
    }
    Ok(FeatureModel {
        format: MODEL_FORMAT,
        classes: classes.to_vec(),
        window: cfg.window,
        edgeboxes: cfg.edgeboxes,
        orientation_interpolation: cfg.orientation_interpolation,
        thresholds: cfg.thresholds,
        nms_iou: cfg.nms_iou,
        hogs,
    })
}

/// Label of a background sample.
const BACKGROUND: ClassId = ClassId::MAX;

fn train_hog(
    frames: &[LabeledFrame],
    plans: &[Plan],
    nclass: usize,
    params: HogParams,
    cfg: &TrainConfig,
) -> Result<HogSvms> {
    let (size, hog) = params.geometry(cfg.window, cfg.orientation_interpolation);
    let dim = hog.len(size, size);
    // Initial sample set, frame by frame in order.
    let per_frame: Vec<(Vec<f32>, Vec<ClassId>)> = frames
        .par_iter()
        .zip(plans)
        .map_init(Buffers::default, |buf, (f, p)| {
            let mut x = Vec::new();
            let mut y = Vec::new();
            let Ok(img) = f.view() else { return (x, y) };
            let samples = p
                .positives
                .iter()
                .copied()
                .chain(p.negatives.iter().map(|b| (BACKGROUND, *b)));
            for (c, b) in samples {
                img.window(&b, size, &mut buf.window);
                hog_into(
                    &buf.window,
                    size,
                    size,
                    3,
                    &hog,
                    &mut buf.hog,
                    &mut buf.feat,
                );
                x.extend_from_slice(&buf.feat);
                y.push(c);
            }
            (x, y)
        })
        .collect();
    let mut x: Vec<f32> = Vec::new();
    let mut y: Vec<ClassId> = Vec::new();
    for (fx, fy) in per_frame {
        x.extend(fx);
        y.extend(fy);
    }
    let mut svms = fit(&x, dim, &y, nclass, &cfg.svm);
    for _ in 0..cfg.mining_rounds {
        let hard: Vec<(Vec<f32>, usize)> = frames
            .par_iter()
            .zip(plans)
            .map_init(Buffers::default, |buf, (f, p)| {
                let mut scored: Vec<(f32, Vec<f32>)> = Vec::new();
                let Ok(img) = f.view() else {
                    return (Vec::new(), 0);
                };
                for b in &p.pool {
                    img.window(b, size, &mut buf.window);
                    hog_into(
                        &buf.window,
                        size,
                        size,
                        3,
                        &hog,
                        &mut buf.hog,
                        &mut buf.feat,
                    );
                    let (_, m) = best_class(&svms, &buf.feat);
                    if m > -1.0 {
                        scored.push((m, buf.feat.clone()));
                    }
                }
                scored.sort_by(|a, b| b.0.total_cmp(&a.0));
                scored.truncate(cfg.hard_per_frame);
                let n = scored.len();
                (scored.into_iter().flat_map(|s| s.1).collect(), n)
            })
            .collect();
        let added: usize = hard.iter().map(|h| h.1).sum();
        if added == 0 {
            break;
        }
        for (hx, n) in hard {
            x.extend(hx);
            y.extend(std::iter::repeat_n(BACKGROUND, n));
        }
        svms = fit(&x, dim, &y, nclass, &cfg.svm);
    }
    Ok(HogSvms {
        block: params.block,
        cell: params.cell,
        bins: params.bins,
        svms,
    })
}

/// One-vs-rest SVMs, trained in parallel over classes.
fn fit(
    x: &[f32],
    dim: usize,
    y: &[ClassId],
    nclass: usize,
    cfg: &SvmConfig,
) -> Vec<crate::svm::LinearSvm> {
    (0..nclass)
        .into_par_iter()
        .map(|k| {
            let labels: Vec<bool> = y.iter().map(|&c| c as usize == k).collect();
            train_svm(x, dim, &labels, cfg)
        })
        .collect()
}
