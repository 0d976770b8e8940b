//! EdgeBoxes object proposals (Zitnick & Dollár, ECCV 2014).
//!
//! The steps follow the paper and its reference implementation:
//!
//! 1. **Edges** — [`crate::edges`] (gradient edges thinned by non-maximum
//!    suppression instead of structured-forest edges).
//! 2. **Edge groups** — starting from each unassigned edge pixel stronger than
//!    [`EdgeBoxesConfig::edge_min_mag`], walk greedily to the 8-connected unassigned
//!    neighbour with the most similar orientation, until the accumulated orientation
//!    change exceeds [`EdgeBoxesConfig::edge_merge_thr`] (in units of π). Groups whose
//!    total magnitude is below [`EdgeBoxesConfig::cluster_min_mag`] are dropped (the
//!    reference merges some of them into neighbours instead).
//! 3. **Affinities** — for groups closer than 2 pixels,
//!    `a(i, j) = |cos(θi − θij) · cos(θj − θij)|^γ`, with θ the groups' mean
//!    orientations and θij the angle between their centroids.
//! 4. **Box score** — groups whose centroid lies in the box count with weight
//!    `1 − max_path Π a` over affinity paths from a group crossing the box boundary;
//!    `h = Σ w·m / ((bw + bh)/2)^κ`, minus the edge magnitude of the central half box.
//! 5. **Search** — boxes slide over scales and aspect ratios with steps chosen so that
//!    neighbours overlap by `α`; the best `refine_limit` boxes scoring above
//!    `min_score` are refined by a coarse-to-fine search over their four sides (down
//!    to 1-pixel steps), then greedy NMS at IoU `β` keeps the best `max_boxes`.
//!
//! Scoring is spread over scales with rayon; results are merged in a fixed order and
//! sorted stably, so proposals are deterministic.
//!
//! One algorithm, its steps in the paper's order (edges, groups, affinities, box
//! scoring, search, NMS); its unit tests are the last 95 lines.

use crate::edges::{EdgeConfig, EdgeMap, edge_map};
use crate::error::{Error, Result};
use crate::frame::Rgb;
use frugal_runtime::BBox;
use rayon::prelude::*;

/// EdgeBoxes settings; the defaults are the reference implementation's except:
///
/// * `min_box_area` 150 (the reference has 1000): signs are 12-110 pixels in 480×270
///   frames;
/// * `max_aspect_ratio` 1 (reference 3): only square boxes slide — signs are square
///   or nearly so, refinement still moves each side on its own, and this divides the
///   sliding cost by three;
/// * `alpha` 0.6 (reference 0.65): a coarser sliding step, enough for IoU 0.5;
/// * `refine_limit`: only the best 4000 boxes are refined.
///
/// With these, on the synthetic test split (every 8th frame), recall at IoU 0.5 was
/// 0.944 / 0.992 / 1.0 / 1.0 for the top 200 / 500 / 1000 / 2000 proposals at
/// ~27 ms of one core per frame, against 0.873 / 0.968 / 0.992 / 0.992 and ~80 ms with
/// `alpha` 0.65, ratio 2 and every box refined.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EdgeBoxesConfig {
    /// Edge detector settings.
    pub edges: EdgeConfig,
    /// Sliding-window step: neighbouring boxes overlap by this IoU.
    pub alpha: f32,
    /// NMS IoU threshold.
    pub beta: f32,
    /// NMS threshold adaptation per kept box (1 = fixed).
    pub eta: f32,
    /// Boxes scoring below this are dropped.
    pub min_score: f32,
    /// Edge pixels weaker than this are ignored.
    pub edge_min_mag: f32,
    /// Orientation change (in units of π) that ends an edge group.
    pub edge_merge_thr: f32,
    /// Edge groups with less total magnitude are dropped.
    pub cluster_min_mag: f32,
    /// Largest width/height (or height/width) ratio searched.
    pub max_aspect_ratio: f32,
    /// Smallest box area searched, in pixels.
    pub min_box_area: f32,
    /// Affinity exponent γ.
    pub gamma: f32,
    /// Box size penalty exponent κ.
    pub kappa: f32,
    /// Only this many of the best-scoring sliding-window boxes are refined (the
    /// reference refines all; refinement is most of the cost).
    pub refine_limit: usize,
}

impl Default for EdgeBoxesConfig {
    fn default() -> Self {
        Self {
            edges: EdgeConfig::default(),
            alpha: 0.6,
            beta: 0.75,
            eta: 1.0,
            min_score: 0.01,
            edge_min_mag: 0.1,
            edge_merge_thr: 0.5,
            cluster_min_mag: 0.5,
            max_aspect_ratio: 1.0,
            min_box_area: 150.0,
            gamma: 2.0,
            kappa: 1.5,
            refine_limit: 4000,
        }
    }
}

impl EdgeBoxesConfig {
    /// Check that every setting is in its valid range.
    pub fn validate(&self) -> Result<()> {
        let bad = |name: &'static str, reason: &str| {
            Err(Error::Param {
                name,
                reason: reason.to_owned(),
            })
        };
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return bad("alpha", "must be in (0, 1)");
        }
        if !(self.beta > 0.0 && self.beta <= 1.0) {
            return bad("beta", "must be in (0, 1]");
        }
        if !(self.eta > 0.0 && self.eta <= 1.0) {
            return bad("eta", "must be in (0, 1]");
        }
        if !(self.max_aspect_ratio >= 1.0 && self.max_aspect_ratio.is_finite()) {
            return bad("max_aspect_ratio", "must be a finite number >= 1");
        }
        if !(self.min_box_area >= 4.0 && self.min_box_area.is_finite()) {
            return bad("min_box_area", "must be a finite number >= 4");
        }
        if !(self.kappa.is_finite() && self.gamma.is_finite() && self.min_score.is_finite()) {
            return bad("kappa/gamma/min_score", "must be finite");
        }
        Ok(())
    }
}

/// A proposal in the reference implementation's integer form: rows `r..=r + h`,
/// columns `c..=c + w`, score `s`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct IBox {
    r: i32,
    c: i32,
    h: i32,
    w: i32,
    s: f32,
}

impl IBox {
    fn bbox(&self) -> BBox {
        BBox::new(
            self.c as f32,
            self.r as f32,
            (self.c + self.w + 1) as f32,
            (self.r + self.h + 1) as f32,
        )
    }
}

/// A scored proposal box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Proposal {
    /// The box.
    pub bbox: BBox,
    /// Its EdgeBoxes score.
    pub score: f32,
}

/// Edge groups of one image with everything box scoring needs.
struct Groups {
    w: usize,
    h: usize,
    /// Total magnitude per group (index 0 = no group).
    mag: Vec<f32>,
    /// Rounded centroid row / column per group.
    row: Vec<i32>,
    col: Vec<i32>,
    /// Affinity lists (CSR): neighbours of group `i` are `aff_idx[aff_start[i]..aff_start[i + 1]]`.
    aff_start: Vec<u32>,
    aff_idx: Vec<u32>,
    aff: Vec<f32>,
    /// Row runs: `h_run[y * w + x]` is the global index of the run of equal group ids
    /// containing pixel `(x, y)`; `h_seg[run]` its group.
    h_run: Vec<u32>,
    h_seg: Vec<u32>,
    /// Column runs, indexed `x * h + y`.
    v_run: Vec<u32>,
    v_seg: Vec<u32>,
    /// Integral image of group magnitudes placed at their centroids, `(w+1) × (h+1)`.
    seg_ii: Vec<f64>,
    /// Integral image of grouped edge magnitudes.
    mag_ii: Vec<f64>,
    /// `scale_norm[k] = k^-κ`.
    scale_norm: Vec<f32>,
}

const UNASSIGNED: u32 = u32::MAX;

fn orient_diff(a: f32, b: f32) -> f32 {
    let v = (a - b).abs() / std::f32::consts::PI;
    if v > 0.5 { 1.0 - v } else { v }
}

impl Groups {
    fn new(e: &EdgeMap, cfg: &EdgeBoxesConfig) -> Self {
        let (w, h) = (e.width, e.height);
        let mut ids: Vec<u32> = e
            .mag
            .iter()
            .map(|&m| if m > cfg.edge_min_mag { UNASSIGNED } else { 0 })
            .collect();
        // Greedy chain walks.
        let mut cnt: u32 = 1;
        for y in 0..h {
            for x in 0..w {
                if ids[y * w + x] != UNASSIGNED {
                    continue;
                }
                let (mut cx, mut cy) = (x, y);
                let mut sum = 0.0f32;
                loop {
                    let i = cy * w + cx;
                    ids[i] = cnt;
                    let o0 = e.orient[i];
                    let mut best: Option<(usize, usize)> = None;
                    let mut best_v = f32::INFINITY;
                    for ny in cy.saturating_sub(1)..=(cy + 1).min(h - 1) {
                        for nx in cx.saturating_sub(1)..=(cx + 1).min(w - 1) {
                            let j = ny * w + nx;
                            if ids[j] != UNASSIGNED {
                                continue;
                            }
                            let v = orient_diff(e.orient[j], o0);
                            if v < best_v {
                                best_v = v;
                                best = Some((nx, ny));
                            }
                        }
                    }
                    match best {
                        Some((nx, ny)) if sum + best_v <= cfg.edge_merge_thr => {
                            sum += best_v;
                            cx = nx;
                            cy = ny;
                        }
                        _ => break,
                    }
                }
                cnt += 1;
            }
        }
        // Group statistics.
        let n = cnt as usize;
        let mut mag = vec![0.0f32; n];
        let mut sx = vec![0.0f64; n];
        let mut sy = vec![0.0f64; n];
        let mut so = vec![(0.0f64, 0.0f64); n];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let g = ids[i] as usize;
                if g == 0 {
                    continue;
                }
                let m = e.mag[i];
                mag[g] += m;
                sx[g] += (m * x as f32) as f64;
                sy[g] += (m * y as f32) as f64;
                let o = 2.0 * e.orient[i] as f64;
                so[g].0 += m as f64 * o.cos();
                so[g].1 += m as f64 * o.sin();
            }
        }
        // Drop weak groups, renumber the rest 1..
        let mut remap = vec![0u32; n];
        let mut kept = 1u32;
        for g in 1..n {
            if mag[g] > cfg.cluster_min_mag {
                remap[g] = kept;
                kept += 1;
            }
        }
        for id in ids.iter_mut() {
            *id = remap[*id as usize];
        }
        let k = kept as usize;
        let mut gmag = vec![0.0f32; k];
        let mut row = vec![0i32; k];
        let mut col = vec![0i32; k];
        let mut orient = vec![0.0f32; k];
        let (mut cxs, mut cys) = (vec![0.0f32; k], vec![0.0f32; k]);
        for g in 1..n {
            let r = remap[g] as usize;
            if r == 0 {
                continue;
            }
            let m = mag[g] as f64;
            gmag[r] = mag[g];
            cxs[r] = (sx[g] / m) as f32;
            cys[r] = (sy[g] / m) as f32;
            col[r] = cxs[r].round() as i32;
            row[r] = cys[r].round() as i32;
            orient[r] = (0.5 * so[g].1.atan2(so[g].0)) as f32;
        }
        // Affinities between groups within 2 pixels of each other.
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        const RAD: usize = 2;
        for y in 0..h {
            for x in 0..w {
                let i = ids[y * w + x];
                if i == 0 {
                    continue;
                }
                for ny in y.saturating_sub(RAD)..=(y + RAD).min(h - 1) {
                    for nx in x.saturating_sub(RAD)..=(x + RAD).min(w - 1) {
                        let j = ids[ny * w + nx];
                        if j != 0 && j != i {
                            pairs.push((i, j));
                        }
                    }
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        let mut aff_start = vec![0u32; k + 1];
        for &(i, _) in &pairs {
            aff_start[i as usize + 1] += 1;
        }
        for g in 0..k {
            aff_start[g + 1] += aff_start[g];
        }
        let aff_idx: Vec<u32> = pairs.iter().map(|p| p.1).collect();
        let aff: Vec<f32> = pairs
            .iter()
            .map(|&(i, j)| {
                let (i, j) = (i as usize, j as usize);
                let t = (cys[j] - cys[i]).atan2(cxs[j] - cxs[i]);
                let a = ((orient[i] - t).cos() * (orient[j] - t).cos()).abs();
                a.powf(cfg.gamma)
            })
            .collect();
        // Runs along rows and columns.
        let mut h_run = vec![0u32; w * h];
        let mut h_seg = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let g = ids[y * w + x];
                if x == 0 || ids[y * w + x - 1] != g {
                    h_seg.push(g);
                }
                h_run[y * w + x] = (h_seg.len() - 1) as u32;
            }
        }
        let mut v_run = vec![0u32; w * h];
        let mut v_seg = Vec::new();
        for x in 0..w {
            for y in 0..h {
                let g = ids[y * w + x];
                if y == 0 || ids[(y - 1) * w + x] != g {
                    v_seg.push(g);
                }
                v_run[x * h + y] = (v_seg.len() - 1) as u32;
            }
        }
        // Integral images.
        let iw = w + 1;
        let mut seg_ii = vec![0.0f64; iw * (h + 1)];
        for g in 1..k {
            let (r, c) = (row[g].clamp(0, h as i32 - 1), col[g].clamp(0, w as i32 - 1));
            seg_ii[(r as usize + 1) * iw + c as usize + 1] += gmag[g] as f64;
        }
        let mut mag_ii = vec![0.0f64; iw * (h + 1)];
        for y in 0..h {
            for x in 0..w {
                if ids[y * w + x] != 0 {
                    mag_ii[(y + 1) * iw + x + 1] = e.mag[y * w + x] as f64;
                }
            }
        }
        for ii in [&mut seg_ii, &mut mag_ii] {
            for y in 1..=h {
                let mut acc = 0.0;
                for x in 1..=w {
                    acc += ii[y * iw + x];
                    ii[y * iw + x] = acc + ii[(y - 1) * iw + x];
                }
            }
        }
        let scale_norm = (0..w + h + 2)
            .map(|s| {
                if s == 0 {
                    1.0
                } else {
                    (s as f32).powf(-cfg.kappa)
                }
            })
            .collect();
        Self {
            w,
            h,
            mag: gmag,
            row,
            col,
            aff_start,
            aff_idx,
            aff,
            h_run,
            h_seg,
            v_run,
            v_seg,
            seg_ii,
            mag_ii,
            scale_norm,
        }
    }

    /// Sum of an integral image over rows `r0..=r1`, columns `c0..=c1`.
    fn area_sum(&self, ii: &[f64], r0: i32, c0: i32, r1: i32, c1: i32) -> f64 {
        let iw = self.w + 1;
        let (r0, c0, r1, c1) = (r0 as usize, c0 as usize, r1 as usize + 1, c1 as usize + 1);
        ii[r1 * iw + c1] - ii[r0 * iw + c1] - ii[r1 * iw + c0] + ii[r0 * iw + c0]
    }

    /// Score `b` in place (clamping it to the image first), as EdgeBoxes' `scoreBox`.
    fn score(&self, b: &mut IBox, s: &mut Scratch, min_score: f32) {
        let (w, h) = (self.w as i32, self.h as i32);
        let r1 = (b.r + b.h).clamp(0, h - 1);
        let r0 = b.r.clamp(0, r1);
        let c1 = (b.c + b.w).clamp(0, w - 1);
        let c0 = b.c.clamp(0, c1);
        b.r = r0;
        b.c = c0;
        b.h = r1 - r0;
        b.w = c1 - c0;
        let (bh, bw) = (b.h / 2, b.w / 2);
        let mut v = self.area_sum(&self.seg_ii, r0, c0, r1, c1);
        let r0m = r0 + bh / 2;
        let c0m = c0 + bw / 2;
        v -= self.area_sum(&self.mag_ii, r0m, c0m, r0m + bh, c0m + bw);
        let norm = self.scale_norm[(bw + bh) as usize];
        if (v as f32) * norm < min_score {
            b.s = 0.0;
            return;
        }
        // Groups crossing the four sides.
        s.stamp = s.stamp.wrapping_add(1);
        if s.stamp == 0 {
            s.done.iter_mut().for_each(|d| *d = 0);
            s.stamp = 1;
        }
        s.ids.clear();
        s.wts.clear();
        let stamp = s.stamp;
        let (wu, hu) = (self.w, self.h);
        let add = |g: u32, s: &mut Scratch| {
            if g != 0 && s.done[g as usize] != stamp {
                s.done[g as usize] = stamp;
                s.map[g as usize] = s.ids.len() as u32;
                s.ids.push(g);
                s.wts.push(1.0);
            }
        };
        for r in [r0, r1] {
            let base = r as usize * wu;
            for run in self.h_run[base + c0 as usize]..=self.h_run[base + c1 as usize] {
                add(self.h_seg[run as usize], s);
            }
        }
        for c in [c0, c1] {
            let base = c as usize * hu;
            for run in self.v_run[base + r0 as usize]..=self.v_run[base + r1 as usize] {
                add(self.v_seg[run as usize], s);
            }
        }
        // Propagate connectedness to the boundary along affinity paths.
        let mut i = 0usize;
        while i < s.ids.len() {
            let wi = s.wts[i];
            let g = s.ids[i] as usize;
            let mut restart = usize::MAX;
            for k in self.aff_start[g] as usize..self.aff_start[g + 1] as usize {
                let q = self.aff_idx[k] as usize;
                let wq = wi * self.aff[k];
                if wq < 0.05 {
                    continue;
                }
                if s.done[q] == stamp {
                    let m = s.map[q] as usize;
                    if wq > s.wts[m] {
                        s.wts[m] = wq;
                        restart = restart.min(m);
                    }
                } else if self.col[q] >= c0
                    && self.col[q] <= c1
                    && self.row[q] >= r0
                    && self.row[q] <= r1
                {
                    s.done[q] = stamp;
                    s.map[q] = s.ids.len() as u32;
                    s.ids.push(q as u32);
                    s.wts.push(wq);
                }
            }
            i = if restart <= i { restart } else { i + 1 };
        }
        for (&g, &wt) in s.ids.iter().zip(&s.wts) {
            let g = g as usize;
            if self.col[g] >= c0 && self.col[g] <= c1 && self.row[g] >= r0 && self.row[g] <= r1 {
                v -= (wt * self.mag[g]) as f64;
            }
        }
        let sc = v as f32 * norm;
        b.s = if sc < min_score { 0.0 } else { sc };
    }

    /// Coarse-to-fine search over the four sides of `b`, as EdgeBoxes' `refineBox`.
    fn refine(&self, b: &mut IBox, s: &mut Scratch, cfg: &EdgeBoxesConfig) {
        let ratio = (1.0 - cfg.alpha) / (1.0 + cfg.alpha);
        let mut r_step = (b.h as f32 * ratio) as i32;
        let mut c_step = (b.w as f32 * ratio) as i32;
        loop {
            // The reference stops above 2-pixel steps; we go down to 1 pixel, because
            // a few pixels of slack cost a 20-pixel sign a lot of IoU.
            r_step /= 2;
            c_step /= 2;
            if r_step < 1 && c_step < 1 {
                break;
            }
            r_step = r_step.max(1);
            c_step = c_step.max(1);
            // (start shift, size change) pairs for each side, tried both ways.
            let moves: [[(i32, i32, i32, i32); 2]; 4] = [
                [(-r_step, 0, r_step, 0), (r_step, 0, -r_step, 0)],
                [(0, 0, r_step, 0), (0, 0, -r_step, 0)],
                [(0, -c_step, 0, c_step), (0, c_step, 0, -c_step)],
                [(0, 0, 0, c_step), (0, 0, 0, -c_step)],
            ];
            for side in moves {
                let mut best = *b;
                for (k, (dr, dc, dh, dw)) in side.into_iter().enumerate() {
                    let mut t = IBox {
                        r: b.r + dr,
                        c: b.c + dc,
                        h: b.h + dh,
                        w: b.w + dw,
                        s: 0.0,
                    };
                    self.score(&mut t, s, cfg.min_score);
                    if t.s > b.s {
                        best = t;
                    }
                    if k == 0 && t.s > b.s {
                        break;
                    }
                }
                *b = best;
            }
        }
    }
}

/// Per-thread scratch space for box scoring.
struct Scratch {
    done: Vec<u32>,
    map: Vec<u32>,
    ids: Vec<u32>,
    wts: Vec<f32>,
    stamp: u32,
}

impl Scratch {
    fn new(groups: usize) -> Self {
        Self {
            done: vec![0; groups],
            map: vec![0; groups],
            ids: Vec::new(),
            wts: Vec::new(),
            stamp: 0,
        }
    }
}

/// IoU of two integer boxes as the reference's `boxesOverlap` (sides `[r, r + h)`).
fn overlap(a: &IBox, b: &IBox) -> f32 {
    let (r1a, c1a, r1b, c1b) = (a.r + a.h, a.c + a.w, b.r + b.h, b.c + b.w);
    if a.r >= r1a || a.c >= c1a || b.r >= r1b || b.c >= c1b {
        return 0.0;
    }
    let ih = (r1a.min(r1b) - a.r.max(b.r)).max(0) as f32;
    let iw = (c1a.min(c1b) - a.c.max(b.c)).max(0) as f32;
    let inter = ih * iw;
    inter / ((a.w * a.h) as f32 + (b.w * b.h) as f32 - inter)
}

/// Greedy NMS over boxes sorted by score, comparing only boxes of similar area
/// (boxes whose areas differ by more than `1/thr` cannot overlap by more than `thr`).
fn nms(boxes: &[IBox], mut thr: f32, eta: f32, max_boxes: usize) -> Vec<IBox> {
    let mut out = Vec::new();
    if thr > 0.99 {
        out.extend(boxes.iter().take(max_boxes).copied());
        return out;
    }
    const NBIN: i32 = 10000;
    let lstep = (1.0 / thr).ln();
    let mut kept: Vec<Vec<IBox>> = vec![Vec::new(); NBIN as usize + 1];
    let mut d = 1i32;
    for b in boxes {
        if out.len() >= max_boxes {
            break;
        }
        let area = ((b.w * b.h) as f32).max(1.0);
        let bin = ((area.ln() / lstep).ceil() as i32).clamp(d, NBIN - d);
        let keep =
            ((bin - d)..=(bin + d)).all(|j| kept[j as usize].iter().all(|k| overlap(b, k) <= thr));
        if keep {
            kept[bin as usize].push(*b);
            out.push(*b);
            if eta < 1.0 && thr > 0.5 {
                thr *= eta;
                d = ((1.0 / thr).ln() / lstep).ceil() as i32;
            }
        }
    }
    out
}

/// EdgeBoxes proposals of an RGB image, best first, at most `max_boxes`.
///
/// Images smaller than 3×3 or without edges give no proposals.
pub fn proposals(img: &Rgb<'_>, cfg: &EdgeBoxesConfig, max_boxes: usize) -> Result<Vec<Proposal>> {
    cfg.validate()?;
    let edges = edge_map(img, &cfg.edges);
    Ok(proposals_from_edges(&edges, cfg, max_boxes))
}

/// EdgeBoxes proposals from a precomputed edge map.
pub fn proposals_from_edges(e: &EdgeMap, cfg: &EdgeBoxesConfig, max_boxes: usize) -> Vec<Proposal> {
    let (w, h) = (e.width, e.height);
    if w < 3 || h < 3 || max_boxes == 0 {
        return Vec::new();
    }
    let groups = Groups::new(e, cfg);
    if groups.mag.len() <= 1 {
        return Vec::new();
    }
    let alpha = cfg.alpha;
    let sc_step = (1.0 / alpha).sqrt();
    let ar_step = (1.0 + alpha) / (2.0 * alpha);
    let rc_ratio = (1.0 - alpha) / (1.0 + alpha);
    let min_size = cfg.min_box_area.sqrt();
    let ar_rad = (cfg.max_aspect_ratio.ln() / (ar_step * ar_step).ln()) as i32;
    let sc_num = ((w.max(h) as f32 / min_size).ln() / sc_step.ln())
        .ceil()
        .max(0.0) as i32;
    let tasks: Vec<(i32, i32)> = (0..sc_num)
        .flat_map(|s| (0..2 * ar_rad + 1).map(move |a| (s, a)))
        .collect();
    let (wi, hi) = (w as i32, h as i32);
    let scored: Vec<Vec<IBox>> = tasks
        .par_iter()
        .map_init(
            || Scratch::new(groups.mag.len()),
            |scratch, &(s, a)| {
                let ar = ar_step.powi(a - ar_rad);
                let sc = min_size * sc_step.powi(s);
                let bh = (sc / ar) as i32;
                let bw = (sc * ar) as i32;
                let kr = 2.max((bh as f32 * rc_ratio) as i32);
                let kc = 2.max((bw as f32 * rc_ratio) as i32);
                let mut out = Vec::new();
                if bh >= hi || bw >= wi || bh < 2 || bw < 2 {
                    return out;
                }
                let mut c = 0;
                while c < wi - bw + kc {
                    let mut r = 0;
                    while r < hi - bh + kr {
                        let mut b = IBox {
                            r,
                            c,
                            h: bh,
                            w: bw,
                            s: 0.0,
                        };
                        groups.score(&mut b, scratch, cfg.min_score);
                        if b.s > 0.0 {
                            out.push(b);
                        }
                        r += kr;
                    }
                    c += kc;
                }
                out
            },
        )
        .collect();
    let mut boxes: Vec<IBox> = scored.into_iter().flatten().collect();
    boxes.sort_by(|a, b| b.s.total_cmp(&a.s));
    let n = boxes.len().min(cfg.refine_limit);
    boxes[..n].par_iter_mut().with_min_len(64).for_each_init(
        || Scratch::new(groups.mag.len()),
        |scratch, b| groups.refine(b, scratch, cfg),
    );
    boxes.sort_by(|a, b| b.s.total_cmp(&a.s));
    nms(&boxes, cfg.beta, cfg.eta, max_boxes)
        .into_iter()
        .map(|b| Proposal {
            bbox: b.bbox(),
            score: b.s,
        })
        .collect()
}

/// Fraction of ground-truth boxes covered by at least one of the first `n` proposals
/// at IoU `>= iou`, for each `n` in `counts`: `(covered, total)` per count.
pub fn recall_at(
    proposals: &[BBox],
    truth: &[BBox],
    counts: &[usize],
    iou: f32,
) -> Vec<(usize, usize)> {
    counts
        .iter()
        .map(|&n| {
            let top = &proposals[..n.min(proposals.len())];
            let hit = truth
                .iter()
                .filter(|t| top.iter().any(|p| p.iou(t) >= iou))
                .count();
            (hit, truth.len())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn canvas(w: usize, h: usize, bg: u8) -> Vec<u8> {
        vec![bg; w * h * 3]
    }

    fn fill(px: &mut [u8], w: usize, b: (usize, usize, usize, usize), rgb: [u8; 3]) {
        for y in b.1..b.3 {
            for x in b.0..b.2 {
                px[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&rgb);
            }
        }
    }

    #[test]
    fn finds_an_isolated_rectangle() {
        let (w, h) = (160usize, 120usize);
        let mut px = canvas(w, h, 40);
        fill(&mut px, w, (50, 30, 90, 70), [220, 30, 30]);
        let img = Rgb::new(w, h, &px).unwrap();
        let props = proposals(&img, &EdgeBoxesConfig::default(), 10).unwrap();
        assert!(!props.is_empty());
        let truth = BBox::new(50.0, 30.0, 90.0, 70.0);
        let best = props[0].bbox;
        assert!(best.iou(&truth) > 0.8, "top proposal {best:?}");
        assert!(props.windows(2).all(|p| p[0].score >= p[1].score));
    }

    #[test]
    fn blank_tiny_and_degenerate_images_give_no_proposals() {
        let cfg = EdgeBoxesConfig::default();
        for (w, h) in [(0usize, 0usize), (1, 1), (0, 10), (2, 2), (64, 48)] {
            let px = canvas(w, h, 128);
            let img = Rgb::new(w, h, &px).unwrap();
            assert!(proposals(&img, &cfg, 100).unwrap().is_empty());
        }
    }

    #[test]
    fn nms_keeps_the_best_of_overlapping_boxes() {
        let a = IBox {
            r: 0,
            c: 0,
            h: 10,
            w: 10,
            s: 3.0,
        };
        let b = IBox {
            r: 1,
            c: 1,
            h: 10,
            w: 10,
            s: 2.0,
        };
        let c = IBox {
            r: 50,
            c: 50,
            h: 10,
            w: 10,
            s: 1.0,
        };
        let kept = nms(&[a, b, c], 0.5, 1.0, 10);
        assert_eq!(kept, vec![a, c]);
        assert_eq!(nms(&[a, b, c], 0.5, 1.0, 1), vec![a]);
    }

    #[test]
    fn recall_counts_covered_truth_boxes() {
        let p = [
            BBox::new(0.0, 0.0, 10.0, 10.0),
            BBox::new(20.0, 20.0, 30.0, 30.0),
        ];
        let t = [
            BBox::new(21.0, 21.0, 31.0, 31.0),
            BBox::new(100.0, 0.0, 110.0, 5.0),
        ];
        assert_eq!(recall_at(&p, &t, &[1, 2], 0.5), vec![(0, 2), (1, 2)]);
    }

    #[test]
    fn invalid_settings_are_errors() {
        let px = canvas(8, 8, 0);
        let img = Rgb::new(8, 8, &px).unwrap();
        let cfg = EdgeBoxesConfig {
            alpha: 1.5,
            ..EdgeBoxesConfig::default()
        };
        assert!(matches!(
            proposals(&img, &cfg, 5),
            Err(Error::Param { name: "alpha", .. })
        ));
    }
}
