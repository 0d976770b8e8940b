//! Pyramidal Lucas-Kanade point tracking (Bouguet's iterative scheme).

use super::Point;
use super::image::{GrayImage, Pyramid};

/// Largest supported window half-size (window `2r + 1` ≤ 21 px).
pub const MAX_WIN_RADIUS: usize = 10;
const MAX_WIN: usize = 2 * MAX_WIN_RADIUS + 1;
const MAX_PATCH: usize = MAX_WIN + 2;

/// Lucas-Kanade parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LkParams {
    /// Window half-size `r`: the window is `(2r + 1)²` pixels, `1 ..= MAX_WIN_RADIUS`.
    pub win_radius: usize,
    /// Pyramid levels used (at most the pyramids' levels).
    pub levels: usize,
    /// Most Gauss-Newton iterations per level.
    pub max_iters: u32,
    /// Stop iterating when the update is shorter than this (pixels).
    pub epsilon: f32,
    /// A point is lost when the smallest eigenvalue of its gradient matrix, divided by
    /// the window area, falls below this (intensity units² per pixel).
    pub min_eigen: f32,
}

impl Default for LkParams {
    /// The tracker's ([`super::TrackerParams::DEFAULT`]).
    fn default() -> Self {
        super::TrackerParams::DEFAULT.lk
    }
}

#[inline]
fn floor_i(v: f32) -> isize {
    let t = v as isize;
    if (t as f32) > v { t - 1 } else { t }
}

/// Samples a `w × h` patch whose top-left sample sits at real position `(x0, y0)` with
/// bilinear interpolation (one set of weights for the whole patch), replicating borders.
fn sample_patch(img: &GrayImage<'_>, x0: f32, y0: f32, w: usize, h: usize, out: &mut [f32]) {
    let (ix, iy) = (floor_i(x0), floor_i(y0));
    let (fx, fy) = (x0 - ix as f32, y0 - iy as f32);
    let (w00, w10, w01, w11) = (
        (1.0 - fx) * (1.0 - fy),
        fx * (1.0 - fy),
        (1.0 - fx) * fy,
        fx * fy,
    );
    let inside =
        ix >= 0 && iy >= 0 && (ix as usize) + w < img.width() && (iy as usize) + h < img.height();
    if inside {
        let (ux, uy) = (ix as usize, iy as usize);
        for (j, orow) in out.chunks_exact_mut(w).take(h).enumerate() {
            let (Some(r0), Some(r1)) = (img.row(uy + j), img.row(uy + j + 1)) else {
                return;
            };
            let (Some(a), Some(b)) = (r0.get(ux..ux + w + 1), r1.get(ux..ux + w + 1)) else {
                return;
            };
            let (a1, b1) = (a.get(1..).unwrap_or(&[]), b.get(1..).unwrap_or(&[]));
            for (o, (((p00, p10), p01), p11)) in
                orow.iter_mut().zip(a.iter().zip(a1).zip(b).zip(b1))
            {
                *o = w00 * f32::from(*p00)
                    + w10 * f32::from(*p10)
                    + w01 * f32::from(*p01)
                    + w11 * f32::from(*p11);
            }
        }
    } else {
        for (j, orow) in out.chunks_exact_mut(w).take(h).enumerate() {
            let y = iy + j as isize;
            for (i, o) in orow.iter_mut().enumerate() {
                let x = ix + i as isize;
                *o = w00 * f32::from(img.clamped(x, y))
                    + w10 * f32::from(img.clamped(x + 1, y))
                    + w01 * f32::from(img.clamped(x, y + 1))
                    + w11 * f32::from(img.clamped(x + 1, y + 1));
            }
        }
    }
}

/// Scratch buffers of one Lucas-Kanade solve (≈ 9 KB): the template's intensities and
/// Scharr gradients, the sampled window and the template patch. Keeping one alive
/// (the [`Tracker`](super::Tracker) does) spares re-initialising them per point.
#[derive(Clone, Debug)]
pub struct LkScratch {
    patch: [f32; MAX_PATCH * MAX_PATCH],
    i: [f32; MAX_WIN * MAX_WIN],
    ix: [f32; MAX_WIN * MAX_WIN],
    iy: [f32; MAX_WIN * MAX_WIN],
    j: [f32; MAX_WIN * MAX_WIN],
}

impl Default for LkScratch {
    fn default() -> Self {
        Self::new()
    }
}

impl LkScratch {
    /// Zeroed buffers.
    pub const fn new() -> Self {
        Self {
            patch: [0.0; MAX_PATCH * MAX_PATCH],
            i: [0.0; MAX_WIN * MAX_WIN],
            ix: [0.0; MAX_WIN * MAX_WIN],
            iy: [0.0; MAX_WIN * MAX_WIN],
            j: [0.0; MAX_WIN * MAX_WIN],
        }
    }

    /// Builds the template around `p` (intensities and Scharr gradients over the
    /// window) and returns the inverse of its 2×2 gradient matrix as `[g11, g12, g22]`;
    /// `None` when the matrix is too weak.
    fn template(
        &mut self,
        img: &GrayImage<'_>,
        p: Point,
        r: usize,
        min_eigen: f32,
    ) -> Option<[f32; 3]> {
        let win = 2 * r + 1;
        let side = win + 2;
        let rf = r as f32;
        let patch = self.patch.get_mut(..side * side)?;
        sample_patch(img, p.x - rf - 1.0, p.y - rf - 1.0, side, side, patch);
        let (mut a11, mut a12, mut a22) = (0f32, 0f32, 0f32);
        let mut rows = patch.chunks_exact(side);
        let (mut up, mut mid) = (rows.next()?, rows.next()?);
        let mut outs = self
            .i
            .chunks_exact_mut(win)
            .zip(self.ix.chunks_exact_mut(win))
            .zip(self.iy.chunks_exact_mut(win));
        for down in rows {
            let ((oi, ox), oy) = outs.next()?;
            let cols = up
                .windows(3)
                .zip(mid.windows(3))
                .zip(down.windows(3))
                .zip(oi.iter_mut().zip(ox.iter_mut()).zip(oy.iter_mut()));
            for (((u, m), d), ((ti, tx), ty)) in cols {
                let (&[u0, u1, u2], &[m0, m1, m2], &[d0, d1, d2]) = (u, m, d) else {
                    continue;
                };
                let gx = (3.0 * (u2 - u0) + 10.0 * (m2 - m0) + 3.0 * (d2 - d0)) * (1.0 / 32.0);
                let gy = (3.0 * (d0 - u0) + 10.0 * (d1 - u1) + 3.0 * (d2 - u2)) * (1.0 / 32.0);
                *ti = m1;
                *tx = gx;
                *ty = gy;
                a11 += gx * gx;
                a12 += gx * gy;
                a22 += gy * gy;
            }
            up = mid;
            mid = down;
        }
        let area = (win * win) as f32;
        let min_eig =
            (a11 + a22 - libm::sqrtf((a11 - a22) * (a11 - a22) + 4.0 * a12 * a12)) / (2.0 * area);
        let det = a11 * a22 - a12 * a12;
        if min_eig.is_nan() || min_eig < min_eigen || det.is_nan() || det <= f32::EPSILON {
            return None;
        }
        Some([a22 / det, -a12 / det, a11 / det])
    }
}

/// Refines `guess` (a position in `next`) so that the window around it matches the
/// window around `p` in `prev`, both at the same pyramid level. `None` when lost.
fn track_level(
    s: &mut LkScratch,
    prev: &GrayImage<'_>,
    next: &GrayImage<'_>,
    p: Point,
    guess: Point,
    prm: &LkParams,
) -> Option<Point> {
    let r = prm.win_radius;
    let win = 2 * r + 1;
    let n = win * win;
    let [g11, g12, g22] = s.template(prev, p, r, prm.min_eigen)?;
    let mut q = guess;
    let rf = r as f32;
    let (wl, hl) = (next.width() as f32, next.height() as f32);
    for _ in 0..prm.max_iters {
        if !(q.x >= -rf && q.y >= -rf && q.x < wl + rf && q.y < hl + rf) {
            return None;
        }
        let js = s.j.get_mut(..n)?;
        sample_patch(next, q.x - rf, q.y - rf, win, win, js);
        let (mut b1, mut b2) = (0f32, 0f32);
        for (((jv, iv), gx), gy) in js.iter().zip(&s.i).zip(&s.ix).zip(&s.iy) {
            let d = iv - jv;
            b1 += d * gx;
            b2 += d * gy;
        }
        let (dx, dy) = (g11 * b1 + g12 * b2, g12 * b1 + g22 * b2);
        q.x += dx;
        q.y += dy;
        if !(q.x.is_finite() && q.y.is_finite()) {
            return None;
        }
        if dx * dx + dy * dy < prm.epsilon * prm.epsilon {
            break;
        }
    }
    (q.x >= -rf && q.y >= -rf && q.x < wl + rf && q.y < hl + rf).then_some(q)
}

/// Tracks `p` (level-0 coordinates in `prev`) into `next`, starting from `guess`
/// (level-0 coordinates in `next`; use `p` when there is no prediction). Coarse to
/// fine over `min(prm.levels, prev.levels(), next.levels())` levels. `None` when the
/// point is lost (weak texture, left the image, diverged).
pub fn track_point(
    prev: &Pyramid<'_>,
    next: &Pyramid<'_>,
    p: Point,
    guess: Point,
    prm: &LkParams,
) -> Option<Point> {
    track_point_with(&mut LkScratch::new(), prev, next, p, guess, prm)
}

/// [`track_point`] with caller-kept scratch buffers.
pub fn track_point_with(
    scratch: &mut LkScratch,
    prev: &Pyramid<'_>,
    next: &Pyramid<'_>,
    p: Point,
    guess: Point,
    prm: &LkParams,
) -> Option<Point> {
    if prm.win_radius == 0
        || prm.win_radius > MAX_WIN_RADIUS
        || prev.width() != next.width()
        || prev.height() != next.height()
    {
        return None;
    }
    let levels = prm.levels.min(prev.levels()).min(next.levels()).max(1);
    let top = levels - 1;
    let scale = (1u32 << top) as f32;
    let mut flow = Point {
        x: (guess.x - p.x) / scale,
        y: (guess.y - p.y) / scale,
    };
    for l in (0..levels).rev() {
        let s = 1.0 / (1u32 << l) as f32;
        let pl = Point {
            x: p.x * s,
            y: p.y * s,
        };
        let g = Point {
            x: pl.x + flow.x,
            y: pl.y + flow.y,
        };
        match track_level(scratch, &prev.level(l)?, &next.level(l)?, pl, g, prm) {
            Some(q) => {
                flow = Point {
                    x: q.x - pl.x,
                    y: q.y - pl.y,
                }
            }
            // A weak or escaped window at a coarse level keeps the guess (as OpenCV does);
            // only level 0 decides that the point is lost.
            None if l > 0 => {}
            None => return None,
        }
        if l > 0 {
            flow.x *= 2.0;
            flow.y *= 2.0;
        }
    }
    Some(Point {
        x: p.x + flow.x,
        y: p.y + flow.y,
    })
}
