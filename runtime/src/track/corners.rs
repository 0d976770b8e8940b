//! Shi-Tomasi ("good features to track") corners inside a region.

use super::Point;
use super::image::GrayImage;
use crate::geom::BBox;

/// Corner detection parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CornerParams {
    /// Keep corners whose response is at least this fraction of the strongest one
    /// (OpenCV's `qualityLevel`).
    pub quality_level: f32,
    /// Least distance between two kept corners, in pixels (OpenCV's `minDistance`).
    pub min_distance: f32,
}

impl Default for CornerParams {
    fn default() -> Self {
        Self {
            quality_level: 0.01,
            min_distance: 4.0,
        }
    }
}

/// A corner candidate: position and min-eigenvalue response.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Corner {
    /// Position (integer pixel centres).
    pub pos: Point,
    /// Smallest eigenvalue of the 3×3-summed structure tensor (Sobel gradients / 8).
    pub response: f32,
}

/// Sobel gradients at `(x, y)`, scaled by 1/8 (so a unit ramp gives 1); the caller
/// guarantees a one-pixel margin.
#[inline]
fn sobel(img: &GrayImage<'_>, x: usize, y: usize) -> (f32, f32) {
    let (Some(r0), Some(r1), Some(r2)) = (img.row(y - 1), img.row(y), img.row(y + 1)) else {
        return (0.0, 0.0);
    };
    let (Some(a), Some(b), Some(c)) = (
        r0.get(x - 1..x + 2),
        r1.get(x - 1..x + 2),
        r2.get(x - 1..x + 2),
    ) else {
        return (0.0, 0.0);
    };
    let (&[a0, a1, a2], &[b0, _, b2], &[c0, c1, c2]) = (a, b, c) else {
        return (0.0, 0.0);
    };
    let f = |v: u8| i32::from(v);
    let gx = (f(a2) - f(a0)) + 2 * (f(b2) - f(b0)) + (f(c2) - f(c0));
    let gy = (f(c0) - f(a0)) + 2 * (f(c1) - f(a1)) + (f(c2) - f(a2));
    (gx as f32 / 8.0, gy as f32 / 8.0)
}

/// Min-eigenvalue response at `(x, y)` over a 3×3 block (needs a two-pixel margin).
#[inline]
fn response(img: &GrayImage<'_>, x: usize, y: usize) -> f32 {
    let (mut a, mut b, mut c) = (0f32, 0f32, 0f32);
    for yy in y - 1..=y + 1 {
        for xx in x - 1..=x + 1 {
            let (gx, gy) = sobel(img, xx, yy);
            a += gx * gx;
            b += gx * gy;
            c += gy * gy;
        }
    }
    0.5 * (a + c - libm::sqrtf((a - c) * (a - c) + 4.0 * b * b))
}

/// Inserts `c` into the kept set `out[..*n]`, keeping corners at least `min_d` apart
/// and the strongest ones when full.
fn insert(out: &mut [Corner], n: &mut usize, c: Corner, min_d2: f32) {
    let kept = out.get(..*n).unwrap_or(&[]);
    let near = |k: &Corner| {
        let (dx, dy) = (k.pos.x - c.pos.x, k.pos.y - c.pos.y);
        dx * dx + dy * dy < min_d2
    };
    if kept.iter().any(|k| near(k) && k.response >= c.response) {
        return;
    }
    // Drop the weaker neighbours c supersedes.
    let mut w = 0;
    for r in 0..*n {
        let Some(k) = out.get(r).copied() else { break };
        if !near(&k) {
            if let Some(slot) = out.get_mut(w) {
                *slot = k;
            }
            w += 1;
        }
    }
    *n = w;
    if *n < out.len() {
        if let Some(slot) = out.get_mut(*n) {
            *slot = c;
            *n += 1;
        }
    } else if let Some(weakest) = out
        .iter_mut()
        .min_by(|a, b| a.response.total_cmp(&b.response))
        .filter(|k| k.response < c.response)
    {
        *weakest = c;
    }
}

/// Finds up to `out.len()` Shi-Tomasi corners inside `region` (clipped to keep a
/// two-pixel image margin), strongest first, at least `min_distance` apart and with a
/// response of at least `quality_level` times the strongest. Returns how many.
///
/// Candidates are the strongest pixel of each `min_distance`-sized cell of the region;
/// a candidate replaces weaker kept corners within `min_distance` of it and is dropped
/// when a stronger one is that close. Work is O(region area + cells · out.len()).
pub fn good_features(
    img: &GrayImage<'_>,
    region: &BBox,
    prm: &CornerParams,
    out: &mut [Corner],
) -> usize {
    let (w, h) = (img.width(), img.height());
    if w < 5 || h < 5 || out.is_empty() || !region.is_valid() {
        return 0;
    }
    let lo = |v: f32| libm::ceilf(v).max(2.0) as usize;
    let x0 = lo(region.x1);
    let y0 = lo(region.y1);
    let x1 = (libm::ceilf(region.x2).max(0.0) as usize).min(w - 2);
    let y1 = (libm::ceilf(region.y2).max(0.0) as usize).min(h - 2);
    if x0 >= x1 || y0 >= y1 {
        return 0;
    }
    let cell = (prm.min_distance.max(1.0) as usize).max(1);
    let min_d2 = prm.min_distance * prm.min_distance;
    let mut n = 0;
    let mut cy = y0;
    while cy < y1 {
        let mut cx = x0;
        while cx < x1 {
            let mut best = Corner::default();
            for y in cy..(cy + cell).min(y1) {
                for x in cx..(cx + cell).min(x1) {
                    let r = response(img, x, y);
                    if r > best.response {
                        best = Corner {
                            pos: Point {
                                x: x as f32,
                                y: y as f32,
                            },
                            response: r,
                        };
                    }
                }
            }
            if best.response > 0.0 {
                insert(out, &mut n, best, min_d2);
            }
            cx += cell;
        }
        cy += cell;
    }
    let kept = out.get_mut(..n).unwrap_or(&mut []);
    kept.sort_unstable_by(|a, b| b.response.total_cmp(&a.response));
    let floor = kept.first().map_or(0.0, |c| c.response * prm.quality_level);
    kept.iter().take_while(|c| c.response >= floor).count()
}
