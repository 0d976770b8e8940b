//! A tiny anti-aliased 2-D rasterizer: shapes are signed-distance functions, and a
//! pixel's coverage is `clamp(0.5 - d / pixel, 0, 1)` at its centre. Good enough for
//! sign pictograms and scene props, and cheap.

/// A 2-D point.
pub type P = (f32, f32);

/// A shape with a signed distance (negative inside) in its own units.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// Disc: centre and radius.
    Disc(P, f32),
    /// Ring: centre, outer and inner radius.
    Ring(P, f32, f32),
    /// Convex polygon, vertices in either winding order.
    Poly(Vec<P>),
    /// Thick line segment with round caps: ends and half-width.
    Seg(P, P, f32),
    /// Axis-aligned rectangle: min corner, max corner, corner radius.
    Rect(P, P, f32),
    /// Union of shapes.
    Union(Vec<Shape>),
    /// The first shape minus the second.
    Minus(Box<Shape>, Box<Shape>),
}

fn len(x: f32, y: f32) -> f32 {
    (x * x + y * y).sqrt()
}

impl Shape {
    /// Signed distance from `p` (negative inside).
    pub fn dist(&self, p: P) -> f32 {
        match self {
            Shape::Disc(c, r) => len(p.0 - c.0, p.1 - c.1) - r,
            Shape::Ring(c, ro, ri) => {
                let d = len(p.0 - c.0, p.1 - c.1);
                (d - ro).max(ri - d)
            }
            Shape::Poly(v) => poly_dist(v, p),
            Shape::Seg(a, b, hw) => seg_dist(*a, *b, p) - hw,
            Shape::Rect(lo, hi, r) => {
                let cx = (lo.0 + hi.0) * 0.5;
                let cy = (lo.1 + hi.1) * 0.5;
                let hx = (hi.0 - lo.0) * 0.5 - r;
                let hy = (hi.1 - lo.1) * 0.5 - r;
                let qx = (p.0 - cx).abs() - hx;
                let qy = (p.1 - cy).abs() - hy;
                len(qx.max(0.0), qy.max(0.0)) + qx.max(qy).min(0.0) - r
            }
            Shape::Union(v) => v.iter().map(|s| s.dist(p)).fold(f32::INFINITY, f32::min),
            Shape::Minus(a, b) => a.dist(p).max(-b.dist(p)),
        }
    }

    /// A conservative bounding box `(min, max)`.
    pub fn bounds(&self) -> (P, P) {
        match self {
            Shape::Disc(c, r) | Shape::Ring(c, r, _) => ((c.0 - r, c.1 - r), (c.0 + r, c.1 + r)),
            Shape::Poly(v) => {
                let mut lo = (f32::INFINITY, f32::INFINITY);
                let mut hi = (f32::NEG_INFINITY, f32::NEG_INFINITY);
                for q in v {
                    lo = (lo.0.min(q.0), lo.1.min(q.1));
                    hi = (hi.0.max(q.0), hi.1.max(q.1));
                }
                (lo, hi)
            }
            Shape::Seg(a, b, hw) => (
                (a.0.min(b.0) - hw, a.1.min(b.1) - hw),
                (a.0.max(b.0) + hw, a.1.max(b.1) + hw),
            ),
            Shape::Rect(lo, hi, _) => (*lo, *hi),
            Shape::Union(v) => {
                let mut lo = (f32::INFINITY, f32::INFINITY);
                let mut hi = (f32::NEG_INFINITY, f32::NEG_INFINITY);
                for s in v {
                    let (a, b) = s.bounds();
                    lo = (lo.0.min(a.0), lo.1.min(a.1));
                    hi = (hi.0.max(b.0), hi.1.max(b.1));
                }
                (lo, hi)
            }
            Shape::Minus(a, _) => a.bounds(),
        }
    }

    /// The shape under an affine map `p -> (p.x * sx + tx, p.y * sy + ty)` (for
    /// distances the mean scale is used; keep `sx ≈ sy`).
    pub fn mapped(&self, sx: f32, sy: f32, tx: f32, ty: f32) -> Shape {
        let m = |p: &P| (p.0 * sx + tx, p.1 * sy + ty);
        let s = (sx.abs() + sy.abs()) * 0.5;
        match self {
            Shape::Disc(c, r) => Shape::Disc(m(c), r * s),
            Shape::Ring(c, ro, ri) => Shape::Ring(m(c), ro * s, ri * s),
            Shape::Poly(v) => Shape::Poly(v.iter().map(m).collect()),
            Shape::Seg(a, b, hw) => Shape::Seg(m(a), m(b), hw * s),
            Shape::Rect(lo, hi, r) => {
                let (a, b) = (m(lo), m(hi));
                Shape::Rect(
                    (a.0.min(b.0), a.1.min(b.1)),
                    (a.0.max(b.0), a.1.max(b.1)),
                    r * s,
                )
            }
            Shape::Union(v) => Shape::Union(v.iter().map(|x| x.mapped(sx, sy, tx, ty)).collect()),
            Shape::Minus(a, b) => Shape::Minus(
                Box::new(a.mapped(sx, sy, tx, ty)),
                Box::new(b.mapped(sx, sy, tx, ty)),
            ),
        }
    }
}

fn seg_dist(a: P, b: P, p: P) -> f32 {
    let (bx, by) = (b.0 - a.0, b.1 - a.1);
    let (px, py) = (p.0 - a.0, p.1 - a.1);
    let l2 = bx * bx + by * by;
    let t = if l2 > 0.0 {
        ((px * bx + py * by) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    len(px - bx * t, py - by * t)
}

/// Signed distance to a convex polygon (exact outside near edges, exact inside).
fn poly_dist(v: &[P], p: P) -> f32 {
    let n = v.len();
    if n < 3 {
        return f32::INFINITY;
    }
    // Winding: positive area means clockwise in y-down screen coordinates.
    let mut area = 0.0;
    for i in 0..n {
        let (a, b) = (v[i], v[(i + 1) % n]);
        area += a.0 * b.1 - b.0 * a.1;
    }
    let sign = if area >= 0.0 { 1.0 } else { -1.0 };
    let mut inside = true;
    let mut best = f32::INFINITY;
    for i in 0..n {
        let (a, b) = (v[i], v[(i + 1) % n]);
        best = best.min(seg_dist(a, b, p));
        let cross = (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0);
        if cross * sign < 0.0 {
            inside = false;
        }
    }
    if inside { -best } else { best }
}

/// A float RGBA canvas in linear-ish `0..1` units, row-major.
#[derive(Clone, Debug)]
pub struct Canvas {
    /// Width.
    pub w: usize,
    /// Height.
    pub h: usize,
    /// `w * h` pixels, RGB.
    pub px: Vec<[f32; 3]>,
}

impl Canvas {
    /// A canvas filled with one colour.
    pub fn new(w: usize, h: usize, fill: [f32; 3]) -> Self {
        Self {
            w,
            h,
            px: vec![fill; w * h],
        }
    }

    /// Paint `shape` in `color` with opacity `alpha`, anti-aliased; returns nothing.
    pub fn fill(&mut self, shape: &Shape, color: [f32; 3], alpha: f32) {
        self.fill_with(shape, alpha, |_, _| color);
    }

    /// Paint `shape` with a per-pixel colour function `f(x, y)`.
    pub fn fill_with(&mut self, shape: &Shape, alpha: f32, f: impl Fn(usize, usize) -> [f32; 3]) {
        let (lo, hi) = shape.bounds();
        let x0 = (lo.0 - 1.0).floor().max(0.0) as usize;
        let y0 = (lo.1 - 1.0).floor().max(0.0) as usize;
        let x1 = ((hi.0 + 1.0).ceil().max(0.0) as usize).min(self.w);
        let y1 = ((hi.1 + 1.0).ceil().max(0.0) as usize).min(self.h);
        for y in y0..y1 {
            for x in x0..x1 {
                let d = shape.dist((x as f32 + 0.5, y as f32 + 0.5));
                let cov = (0.5 - d).clamp(0.0, 1.0) * alpha;
                if cov > 0.0 {
                    let c = f(x, y);
                    let p = &mut self.px[y * self.w + x];
                    for k in 0..3 {
                        p[k] += (c[k] - p[k]) * cov;
                    }
                }
            }
        }
    }
}

/// Coverage of `shape` at the centre of each pixel of a `w × h` grid (for masks).
pub fn coverage(shape: &Shape, w: usize, h: usize) -> Vec<f32> {
    let mut out = vec![0.0; w * h];
    for_each_coverage(shape, w, h, |x, y, c| out[y * w + x] = c);
    out
}

/// Call `f(x, y, coverage)` for every pixel of a `w × h` grid that `shape` touches.
pub fn for_each_coverage(shape: &Shape, w: usize, h: usize, mut f: impl FnMut(usize, usize, f32)) {
    let (lo, hi) = shape.bounds();
    let x0 = (lo.0 - 1.0).floor().max(0.0) as usize;
    let y0 = (lo.1 - 1.0).floor().max(0.0) as usize;
    let x1 = ((hi.0 + 1.0).ceil().max(0.0) as usize).min(w);
    let y1 = ((hi.1 + 1.0).ceil().max(0.0) as usize).min(h);
    for y in y0..y1 {
        for x in x0..x1 {
            let c = (0.5 - shape.dist((x as f32 + 0.5, y as f32 + 0.5))).clamp(0.0, 1.0);
            if c > 0.0 {
                f(x, y, c);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_have_the_right_sign_and_size() {
        let d = Shape::Disc((0.0, 0.0), 2.0);
        assert!((d.dist((0.0, 0.0)) + 2.0).abs() < 1e-6);
        assert!((d.dist((5.0, 0.0)) - 3.0).abs() < 1e-6);
        let sq = Shape::Poly(vec![(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)]);
        let sq_ccw = Shape::Poly(vec![(0.0, 0.0), (0.0, 2.0), (2.0, 2.0), (2.0, 0.0)]);
        for s in [&sq, &sq_ccw] {
            assert!((s.dist((1.0, 1.0)) + 1.0).abs() < 1e-6);
            assert!((s.dist((3.0, 1.0)) - 1.0).abs() < 1e-6);
        }
        let r = Shape::Rect((0.0, 0.0), (2.0, 2.0), 0.0);
        assert!((r.dist((3.0, 1.0)) - 1.0).abs() < 1e-6);
        assert!((r.dist((1.0, 1.0)) + 1.0).abs() < 1e-6);
        let ring = Shape::Ring((0.0, 0.0), 2.0, 1.0);
        assert!(ring.dist((0.0, 0.0)) > 0.0 && ring.dist((1.5, 0.0)) < 0.0);
        let cut = Shape::Minus(Box::new(sq), Box::new(Shape::Disc((1.0, 1.0), 0.5)));
        assert!(cut.dist((1.0, 1.0)) > 0.0 && cut.dist((0.2, 0.2)) < 0.0);
    }

    #[test]
    fn coverage_is_antialiased_and_area_preserving() {
        let disc = Shape::Disc((10.0, 10.0), 6.0);
        let cov = coverage(&disc, 20, 20);
        let area: f32 = cov.iter().sum();
        assert!(
            (area - std::f32::consts::PI * 36.0).abs() < 2.0,
            "area {area}"
        );
        assert!(
            cov.iter().any(|&c| c > 0.05 && c < 0.95),
            "edges are partial"
        );
    }
}
