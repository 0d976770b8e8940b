//! Learning the budget tables: samples from paired segments, shrinkage towards content
//! and action means, Lagrangian value iteration per budget with λ bisected on training
//! rollouts.

use crate::error::Result;
use crate::replay::{Frames, ReplayLog, VideoLog};
use crate::scoring::TrackerCost;
use frugal_data::Split;
use frugal_runtime::BBox;
use frugal_runtime::bundle::BUCKET_COUNT;
use frugal_runtime::schedule::{CONTENT_STATES, state_index};
use std::collections::HashMap;

use super::segments::{LastBox, content_after};
use super::{BudgetConfig, BudgetPolicies, BudgetPolicy, Segment, video_segments};

/// A sample of the semi-MDP.
#[derive(Clone, Copy, Debug)]
struct Sample {
    s: usize,
    a: usize,
    reward: f64,
    cost_ms: f64,
    len: usize,
    next: usize,
}

/// The median interval between consecutive frames of `videos` as they arrive
/// ([`VideoLog::arrivals_ms`]: their own times, else `fps`), ms: the clock the tables
/// learnt on them count. `1000 / fps` when no video has two frames.
fn frame_interval_ms(videos: &[&VideoLog], fps: f64) -> f64 {
    let mut gaps = Vec::new();
    for v in videos {
        let a = v.arrivals_ms(fps);
        gaps.extend(
            a.windows(2)
                .map(|w| w[1] - w[0])
                .filter(|g| g.is_finite() && *g > 0.0),
        );
    }
    if gaps.is_empty() {
        1e3 / fps
    } else {
        crate::scoring::median(&mut gaps)
    }
}

/// Learn the budget policies from the log's training videos.
pub fn train_budget(
    log: &ReplayLog,
    frames: &dyn Frames,
    cost: TrackerCost,
    cfg: &BudgetConfig,
    iou: f32,
) -> Result<BudgetPolicies> {
    cfg.check(std::path::Path::new("<budget config>"))?;
    let train: Vec<&VideoLog> = if log.split(Split::Train).next().is_some() {
        log.split(Split::Train).collect()
    } else {
        log.videos.iter().collect()
    };
    let v_n = log.variants.len();
    let p_n = cfg.periods.len();
    let a_n = v_n * p_n;
    let s_n = BUCKET_COUNT * v_n * CONTENT_STATES;
    let edges = cfg.edges();
    // every frame is read by up to `periods.last()` segments of every variant: decode
    // each video once; videos in parallel
    let segs: Vec<Vec<Vec<Segment>>> = {
        use rayon::prelude::*;
        train
            .par_iter()
            .map(|v| {
                let cached = crate::replay::MemoryFrames::of_video(frames, v)?;
                video_segments(log, v, &cached, cost, cfg, iou)
            })
            .collect::<Result<_>>()?
    };
    let seg_len = |seg: &Segment, period: usize| seg.frames.len().min(cfg.periods[period] as usize);
    let seg_cost = |seg: &Segment, len: usize| -> f64 {
        seg.frames[..len].iter().map(|f| f.3).sum::<f64>() * cfg.slowdown
    };
    // the state a segment leaves: bucket of its score on its variant, the variant, content
    let leave = |v: usize, seg: &Segment, len: usize, prev: Option<(i64, BBox)>| {
        let boxes: Vec<(usize, Option<BBox>)> =
            seg.frames[..len].iter().map(|f| (f.1, f.2)).collect();
        let (content, last) = content_after(&edges, prev, &boxes);
        let bucket = log.buckets(v).to_runtime().bucket(seg.score);
        (state_index(bucket, v as u16, content, v_n), last)
    };
    let mut samples: Vec<Sample> = Vec::new();
    let mut action_cost = vec![(0.0f64, 0usize); a_n];
    let mut variant_f1 = vec![(0.0f64, 0usize); v_n];
    let mut approx = vec![(0.0f64, 0usize); CONTENT_STATES * a_n];
    for video in &segs {
        let n = video.len();
        for t in 0..n {
            for (acc, seg) in variant_f1.iter_mut().zip(&video[t]) {
                acc.0 += seg.frames[0].0;
                acc.1 += 1;
            }
            // states that segments ending at t leave: (state, variant, its last box)
            let mut entering: Vec<(usize, usize, LastBox)> = Vec::new();
            for (p0, &period) in cfg.periods.iter().enumerate() {
                let Some(start) = t.checked_sub(period as usize) else {
                    continue;
                };
                for (v0, seg) in video[start].iter().enumerate() {
                    if seg_len(seg, p0) != cfg.periods[p0] as usize {
                        continue; // that segment ended earlier (lost track) or is shorter
                    }
                    let (s, last) = leave(v0, seg, cfg.periods[p0] as usize, None);
                    entering.push((s, v0, last));
                }
            }
            for (v, seg) in video[t].iter().enumerate() {
                for p in 0..p_n {
                    let len = seg_len(seg, p);
                    let a = cfg.action(v, p);
                    let c = seg_cost(seg, len);
                    action_cost[a].0 += c / len as f64;
                    action_cost[a].1 += 1;
                    let reward: f64 = seg.frames[..len].iter().map(|f| f.0).sum();
                    for &(s, v0, last) in &entering {
                        let (next, _) = leave(v, seg, len, last);
                        let content = s % CONTENT_STATES;
                        approx[content * a_n + a].0 += reward / len as f64;
                        approx[content * a_n + a].1 += 1;
                        samples.push(Sample {
                            s,
                            a,
                            reward: reward - if v != v0 { cfg.switch_cost } else { 0.0 },
                            cost_ms: c,
                            len,
                            next,
                        });
                    }
                }
            }
        }
    }
    let mean = |(s, n): (f64, usize)| if n > 0 { s / n as f64 } else { 0.0 };
    let action_ms: Vec<f64> = action_cost.iter().copied().map(mean).collect();
    let model = Model::estimate(&samples, s_n, a_n, cfg);
    let variant_device_ms: Vec<f64> = log
        .variants
        .iter()
        .map(|v| v.latency_ms * cfg.slowdown)
        .collect();
    let cheapest = (0..v_n)
        .min_by(|&a, &b| variant_device_ms[a].total_cmp(&variant_device_ms[b]))
        .unwrap_or(0);
    let mut out = BudgetPolicies {
        config: cfg.clone(),
        variants: log.variants.iter().map(|v| v.name.clone()).collect(),
        variant_device_ms,
        initial: cfg.action(cheapest, 0) as u16,
        policies: Vec::new(),
        approx_f1: approx.iter().copied().map(mean).collect(),
        action_ms,
        variant_f1: variant_f1.iter().copied().map(mean).collect(),
        tracker_cost: Some(cost),
        frame_ms: Some(frame_interval_ms(&train, cfg.fps)),
    };
    // the first detection reads the table at the state the scheduler starts in: the miss
    // bucket, the initial variant, nothing shown
    let start = state_index(
        frugal_runtime::bundle::Bucket::Miss,
        cheapest as u16,
        frugal_runtime::schedule::Content::default(),
        v_n,
    );
    for &budget in &cfg.budgets_ms {
        let allowed = out.choices(budget);
        let solve = |lambda: f64| {
            let actions = model.solve(budget, lambda, cfg, &allowed);
            let first = actions[start];
            let (ms, p95, f1) = rollout(&segs, &actions, first, cfg, &leave, &seg_len, &seg_cost);
            (actions, ms, p95, f1)
        };
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        let mut best = solve(0.0);
        if best.1 > budget {
            // grow λ until the budget holds (or give up at a very large price)
            let mut found = None;
            while hi < 1e4 {
                let r = solve(hi);
                if r.1 <= budget {
                    found = Some(r);
                    break;
                }
                lo = hi;
                hi *= 4.0;
            }
            match found {
                None => best = solve(hi),
                Some(r) => {
                    best = r;
                    for _ in 0..20 {
                        let mid = 0.5 * (lo + hi);
                        let r = solve(mid);
                        if r.1 <= budget {
                            hi = mid;
                            best = r;
                        } else {
                            lo = mid;
                        }
                    }
                }
            }
        } else {
            hi = 0.0;
        }
        out.policies.push(BudgetPolicy {
            budget_ms: budget,
            lambda: hi,
            expected_ms: best.1,
            p95_ms: best.2,
            train_f1: best.3,
            actions: best.0.iter().map(|&a| a as u16).collect(),
            search: None,
        });
    }
    Ok(out)
}

/// Roll a policy out on the training segments from action `first`: (device ms per frame
/// overall, its 95th percentile over videos, mean per-frame F1).
#[allow(clippy::type_complexity)]
fn rollout(
    segs: &[Vec<Vec<Segment>>],
    actions: &[usize],
    first: usize,
    cfg: &BudgetConfig,
    leave: &dyn Fn(usize, &Segment, usize, Option<(i64, BBox)>) -> (usize, Option<(i64, BBox)>),
    seg_len: &dyn Fn(&Segment, usize) -> usize,
    seg_cost: &dyn Fn(&Segment, usize) -> f64,
) -> (f64, f64, f64) {
    let p_n = cfg.periods.len();
    let (mut ms, mut frames, mut f1) = (0.0, 0usize, 0.0);
    let mut per_video = Vec::new();
    for video in segs {
        let (mut t, mut a, mut last) = (0usize, first, None);
        let (mut vms, mut vframes) = (0.0, 0usize);
        while t < video.len() {
            let (v, p) = (a / p_n, a % p_n);
            let seg = &video[t][v];
            let len = seg_len(seg, p);
            vms += seg_cost(seg, len);
            f1 += seg.frames[..len].iter().map(|f| f.0).sum::<f64>();
            vframes += len;
            let (s, l) = leave(v, seg, len, last);
            last = l;
            a = actions[s];
            t += len;
        }
        ms += vms;
        frames += vframes;
        per_video.push(vms / vframes.max(1) as f64);
    }
    per_video.sort_by(f64::total_cmp);
    let p95 = crate::stream::nearest_rank(&per_video, 0.95);
    (ms / frames.max(1) as f64, p95, f1 / frames.max(1) as f64)
}

/// The estimated semi-MDP: per (state, action), smoothed reward, cost, frames, and
/// next states with their expected discount `E[γ^L]`.
struct Model {
    s_n: usize,
    a_n: usize,
    reward: Vec<f64>,
    cost: Vec<f64>,
    len: Vec<f64>,
    next: Vec<Vec<(usize, f64)>>,
}

impl Model {
    fn estimate(samples: &[Sample], s_n: usize, a_n: usize, cfg: &BudgetConfig) -> Model {
        #[derive(Default, Clone)]
        struct Acc {
            n: f64,
            reward: f64,
            cost: f64,
            len: f64,
            next: HashMap<usize, f64>,
        }
        impl Acc {
            fn add(&mut self, x: &Sample, gamma: f64) {
                self.n += 1.0;
                self.reward += x.reward;
                self.cost += x.cost_ms;
                self.len += x.len as f64;
                *self.next.entry(x.next).or_default() += gamma.powi(x.len as i32);
            }
        }
        let content = |s: usize| s % CONTENT_STATES;
        let mut fine = vec![Acc::default(); s_n * a_n];
        let mut coarse = vec![Acc::default(); CONTENT_STATES * a_n];
        let mut action = vec![Acc::default(); a_n];
        for x in samples {
            fine[x.s * a_n + x.a].add(x, cfg.gamma);
            coarse[content(x.s) * a_n + x.a].add(x, cfg.gamma);
            action[x.a].add(x, cfg.gamma);
        }
        let m = cfg.smoothing;
        // shrink `a` towards `prior` (given as means and a next-state distribution)
        let shrink = |a: &Acc, prior: &(f64, f64, f64, Vec<(usize, f64)>)| {
            let w = a.n + m;
            if w <= 0.0 {
                return prior.clone();
            }
            let r = (a.reward + m * prior.0) / w;
            let c = (a.cost + m * prior.1) / w;
            let l = (a.len + m * prior.2) / w;
            let mut next: HashMap<usize, f64> = HashMap::new();
            for (&s, &g) in &a.next {
                *next.entry(s).or_default() += g / w;
            }
            for &(s, g) in &prior.3 {
                *next.entry(s).or_default() += g * m / w;
            }
            let mut next: Vec<(usize, f64)> = next.into_iter().collect();
            next.sort_by_key(|x| x.0);
            (r, c, l, next)
        };
        let as_prior = |a: &Acc| {
            let n = a.n.max(1.0);
            let mut next: Vec<(usize, f64)> = a.next.iter().map(|(&s, &g)| (s, g / n)).collect();
            next.sort_by_key(|x| x.0);
            (a.reward / n, a.cost / n, a.len / n, next)
        };
        let action_prior: Vec<_> = action.iter().map(as_prior).collect();
        let coarse_prior: Vec<_> = (0..CONTENT_STATES * a_n)
            .map(|i| shrink(&coarse[i], &action_prior[i % a_n]))
            .collect();
        let mut model = Model {
            s_n,
            a_n,
            reward: vec![0.0; s_n * a_n],
            cost: vec![0.0; s_n * a_n],
            len: vec![1.0; s_n * a_n],
            next: vec![Vec::new(); s_n * a_n],
        };
        for s in 0..s_n {
            for a in 0..a_n {
                let (r, c, l, next) =
                    shrink(&fine[s * a_n + a], &coarse_prior[content(s) * a_n + a]);
                model.reward[s * a_n + a] = r;
                model.cost[s * a_n + a] = c;
                model.len[s * a_n + a] = l.max(1.0);
                model.next[s * a_n + a] = next;
            }
        }
        model
    }

    /// Value iteration of the Lagrangian reward; the greedy action per state.
    fn solve(&self, budget: f64, lambda: f64, cfg: &BudgetConfig, allowed: &[usize]) -> Vec<usize> {
        let s_n = self.s_n;
        let a_n = self.a_n;
        let q = |s: usize, a: usize, v: &[f64]| {
            let i = s * a_n + a;
            let r = self.reward[i] - lambda * (self.cost[i] / budget - self.len[i]);
            r + self.next[i].iter().map(|&(s2, g)| g * v[s2]).sum::<f64>()
        };
        let mut v = vec![0.0; s_n];
        let tol = 1e-6 * (1.0 - cfg.gamma);
        for _ in 0..10_000 {
            let mut delta = 0.0f64;
            let nv: Vec<f64> = (0..s_n)
                .map(|s| {
                    allowed
                        .iter()
                        .map(|&a| q(s, a, &v))
                        .fold(f64::NEG_INFINITY, f64::max)
                })
                .collect();
            for (a, b) in nv.iter().zip(&v) {
                delta = delta.max((a - b).abs());
            }
            v = nv;
            if delta < tol {
                break;
            }
        }
        (0..s_n)
            .map(|s| {
                let mut best = allowed.first().copied().unwrap_or(0);
                let mut bq = f64::NEG_INFINITY;
                for &a in allowed {
                    let x = q(s, a, &v);
                    if x > bq + 1e-12 {
                        bq = x;
                        best = a;
                    }
                }
                best
            })
            .collect()
    }
}
