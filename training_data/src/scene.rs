//! Warehouse-like backgrounds: a wall with panels and posters, a concrete floor with
//! aisle markings, racks with boxes and bins, people, and sign-like distractors
//! (discs, triangles, octagons, diamonds that are not signs). One background
//! ("world") is drawn per video, larger than the frame; the camera looks at a moving
//! window of it.
use crate::Clutter;
use crate::raster::{Canvas, P, Shape};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Smooth random field in about `-1..1`: random values on a grid of `cell` pixels,
/// bilinearly interpolated with a smoothstep.
pub struct ValueNoise {
    gw: usize,
    cell: f32,
    vals: Vec<f32>,
}

impl ValueNoise {
    /// A field covering `w × h` pixels.
    pub fn new(rng: &mut ChaCha8Rng, w: usize, h: usize, cell: f32) -> Self {
        let gw = (w as f32 / cell) as usize + 2;
        let gh = (h as f32 / cell) as usize + 2;
        let vals = (0..gw * gh).map(|_| rng.random_range(-1.0..1.0)).collect();
        Self { gw, cell, vals }
    }

    /// The field at `(x, y)`.
    pub fn at(&self, x: f32, y: f32) -> f32 {
        let fx = (x / self.cell).max(0.0);
        let fy = (y / self.cell).max(0.0);
        let (ix, iy) = (fx as usize, fy as usize);
        let gh = self.vals.len() / self.gw;
        let ix = ix.min(self.gw - 2);
        let iy = iy.min(gh - 2);
        let s = |t: f32| {
            let t = t.clamp(0.0, 1.0);
            t * t * (3.0 - 2.0 * t)
        };
        let (tx, ty) = (s(fx - ix as f32), s(fy - iy as f32));
        let v = |a: usize, b: usize| self.vals[b * self.gw + a];
        let top = v(ix, iy) + (v(ix + 1, iy) - v(ix, iy)) * tx;
        let bot = v(ix, iy + 1) + (v(ix + 1, iy + 1) - v(ix, iy + 1)) * tx;
        top + (bot - top) * ty
    }
}

fn pick<T: Copy>(rng: &mut ChaCha8Rng, items: &[T]) -> T {
    items[rng.random_range(0..items.len())]
}

fn jitter(rng: &mut ChaCha8Rng, c: [f32; 3], amount: f32) -> [f32; 3] {
    let k = 1.0 + rng.random_range(-amount..amount);
    c.map(|v| (v * k + rng.random_range(-amount..amount) * 0.3).clamp(0.0, 1.0))
}

/// How strongly props stand out (1 = full colour, lower = mixed towards the wall).
fn contrast(clutter: Clutter) -> f32 {
    match clutter {
        Clutter::Low => 0.55,
        Clutter::Medium => 0.8,
        Clutter::High => 1.0,
    }
}

fn mix(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

/// Sign-like distractor colours: saturated like signs, but no sign's design.
const DISTRACTOR_COLORS: [[f32; 3]; 7] = [
    [0.80, 0.08, 0.10],
    [0.05, 0.30, 0.68],
    [0.95, 0.78, 0.05],
    [0.10, 0.55, 0.25],
    [0.95, 0.45, 0.05],
    [0.94, 0.94, 0.92],
    [0.55, 0.10, 0.55],
];

fn regular_polygon(c: P, r: f32, n: usize, rot: f32) -> Shape {
    Shape::Poly(
        (0..n)
            .map(|k| {
                let a = rot + k as f32 * std::f32::consts::TAU / n as f32;
                (c.0 + r * a.cos(), c.1 + r * a.sin())
            })
            .collect(),
    )
}

/// One sign-like distractor centred at `c` with radius `r`.
fn distractor(canvas: &mut Canvas, rng: &mut ChaCha8Rng, c: P, r: f32, wall: [f32; 3], k: f32) {
    let color = mix(wall, pick(rng, &DISTRACTOR_COLORS), k);
    let rim = mix(wall, [0.93, 0.93, 0.9], k);
    let kind = rng.random_range(0..6);
    let outer = match kind {
        0 => Shape::Disc(c, r),
        1 => regular_polygon(c, r, 3, -std::f32::consts::FRAC_PI_2),
        2 => regular_polygon(c, r, 8, std::f32::consts::PI / 8.0),
        3 => regular_polygon(c, r, 4, 0.0),
        4 => Shape::Rect((c.0 - r, c.1 - r), (c.0 + r, c.1 + r), r * 0.15),
        _ => regular_polygon(c, r, 3, std::f32::consts::FRAC_PI_2),
    };
    let has_rim = rng.random_bool(0.5);
    if has_rim {
        canvas.fill(&outer, rim, 1.0);
        let inner = outer.mapped(0.88, 0.88, c.0 * 0.12, c.1 * 0.12);
        canvas.fill(&inner, color, 1.0);
    } else {
        canvas.fill(&outer, color, 1.0);
    }
    // A mark that no sign has: a centred dot, a vertical bar or a ring.
    let mark = mix(
        wall,
        pick(
            rng,
            &[[0.07, 0.07, 0.08], [0.94, 0.94, 0.92], [0.95, 0.78, 0.05]],
        ),
        k,
    );
    match rng.random_range(0..4) {
        0 => canvas.fill(&Shape::Disc(c, r * 0.3), mark, 1.0),
        1 => canvas.fill(
            &Shape::Seg((c.0, c.1 - r * 0.45), (c.0, c.1 + r * 0.45), r * 0.12),
            mark,
            1.0,
        ),
        2 => canvas.fill(&Shape::Ring(c, r * 0.55, r * 0.4), mark, 1.0),
        _ => {}
    }
}

fn person(canvas: &mut Canvas, rng: &mut ChaCha8Rng, feet: P, h: f32, k: f32, wall: [f32; 3]) {
    let clothes = mix(
        wall,
        pick(
            rng,
            &[
                [0.15, 0.17, 0.22],
                [0.25, 0.22, 0.2],
                [0.1, 0.1, 0.12],
                [0.3, 0.32, 0.4],
            ],
        ),
        k,
    );
    let skin = mix(wall, jitter(rng, [0.62, 0.47, 0.38], 0.2), k);
    let u = h / 8.0;
    let (x, y) = feet;
    let hip = (x, y - 4.0 * u);
    let stride = rng.random_range(-0.8..0.8) * u;
    canvas.fill(
        &Shape::Seg(hip, (x - u * 0.5 + stride, y - u * 0.2), u * 0.42),
        clothes,
        1.0,
    );
    canvas.fill(
        &Shape::Seg(hip, (x + u * 0.5 - stride, y - u * 0.2), u * 0.42),
        clothes,
        1.0,
    );
    let torso = Shape::Rect(
        (x - u * 0.95, y - 7.0 * u),
        (x + u * 0.95, y - 3.7 * u),
        u * 0.5,
    );
    let vest = rng.random_bool(0.4);
    let top = if vest {
        mix(wall, [0.95, 0.85, 0.1], k)
    } else {
        clothes
    };
    canvas.fill(&torso, top, 1.0);
    canvas.fill(
        &Shape::Seg((x - u, y - 6.6 * u), (x - u * 1.2, y - 4.2 * u), u * 0.32),
        top,
        1.0,
    );
    canvas.fill(
        &Shape::Seg((x + u, y - 6.6 * u), (x + u * 1.2, y - 4.2 * u), u * 0.32),
        top,
        1.0,
    );
    canvas.fill(&Shape::Disc((x, y - 7.6 * u), u * 0.62), skin, 1.0);
}

/// A rack's footprint: left edge, floor line, width and height.
struct RackBox {
    x0: f32,
    base: f32,
    w: f32,
    h: f32,
}

fn rack(canvas: &mut Canvas, rng: &mut ChaCha8Rng, rb: RackBox, clutter: Clutter, wall: [f32; 3]) {
    let RackBox { x0, base, w, h } = rb;
    let k = contrast(clutter);
    let frame = mix(
        wall,
        pick(
            rng,
            &[[0.85, 0.42, 0.10], [0.12, 0.28, 0.55], [0.45, 0.47, 0.5]],
        ),
        k,
    );
    let levels = rng.random_range(3..=4);
    let post = (w * 0.03).max(2.0);
    let fill_prob = match clutter {
        Clutter::Low => 0.45,
        Clutter::Medium => 0.7,
        Clutter::High => 0.92,
    };
    for l in 0..levels {
        let beam_y = base - h * l as f32 / levels as f32;
        let shelf_h = h / levels as f32;
        // Boxes standing on this beam.
        let mut x = x0 + post * 1.5;
        while x < x0 + w - post * 2.0 {
            let bw = rng.random_range(0.08..0.3) * w;
            let bw = bw.min(x0 + w - post * 1.5 - x);
            if bw < 4.0 {
                break;
            }
            if rng.random_bool(fill_prob) {
                let bh = shelf_h * rng.random_range(0.35..0.85);
                let bin = clutter != Clutter::Low && rng.random_bool(0.2);
                let base_color = if bin {
                    pick(
                        rng,
                        &[
                            [0.12, 0.3, 0.7],
                            [0.8, 0.15, 0.1],
                            [0.9, 0.75, 0.1],
                            [0.2, 0.55, 0.3],
                        ],
                    )
                } else {
                    jitter(rng, [0.66, 0.5, 0.32], 0.15)
                };
                let c = mix(wall, base_color, k);
                let r = Shape::Rect((x, beam_y - bh), (x + bw - 1.0, beam_y), 0.5);
                canvas.fill(&r, c, 1.0);
                if !bin {
                    let tape = mix(c, [0.85, 0.75, 0.55], 0.5);
                    let cx = x + bw * 0.5;
                    canvas.fill(
                        &Shape::Rect((cx - bw * 0.06, beam_y - bh), (cx + bw * 0.06, beam_y), 0.0),
                        tape,
                        1.0,
                    );
                    if rng.random_bool(0.4) {
                        let lw = bw * 0.3;
                        let lab = Shape::Rect(
                            (x + bw * 0.1, beam_y - bh * 0.5),
                            (x + bw * 0.1 + lw, beam_y - bh * 0.5 + lw * 0.6),
                            0.0,
                        );
                        canvas.fill(&lab, mix(wall, [0.95, 0.95, 0.93], k), 1.0);
                    }
                }
            }
            x += bw + rng.random_range(1.0..6.0);
        }
        let beam = Shape::Rect((x0, beam_y - post * 1.2), (x0 + w, beam_y), 0.0);
        canvas.fill(&beam, frame, 1.0);
    }
    let top = Shape::Rect((x0, base - h - post), (x0 + w, base - h), 0.0);
    canvas.fill(&top, frame, 1.0);
    for px in [x0, x0 + w - post] {
        canvas.fill(
            &Shape::Rect((px, base - h - post), (px + post, base), 0.0),
            frame,
            1.0,
        );
    }
}

/// Draw a `w × h` warehouse background for one video.
pub fn draw_world(rng: &mut ChaCha8Rng, w: usize, h: usize, clutter: Clutter) -> Canvas {
    let k = contrast(clutter);
    let wall0 = pick(
        rng,
        &[
            [0.78, 0.77, 0.72],
            [0.70, 0.74, 0.76],
            [0.82, 0.80, 0.74],
            [0.62, 0.64, 0.62],
        ],
    );
    let wall = jitter(rng, wall0, 0.06);
    let floor0 = pick(
        rng,
        &[[0.55, 0.55, 0.53], [0.50, 0.47, 0.42], [0.60, 0.58, 0.55]],
    );
    let floor = jitter(rng, floor0, 0.06);
    let horizon = h as f32 * rng.random_range(0.55..0.64);
    let (wf, hf) = (w as f32, h as f32);
    let mut canvas = Canvas::new(w, h, wall);

    // Wall and floor textures.
    let coarse = ValueNoise::new(rng, w, h, 48.0);
    let fine = ValueNoise::new(rng, w, h, 7.0);
    let seam = rng.random_range(50.0..110.0);
    for y in 0..h {
        for x in 0..w {
            let (xf, yf) = (x as f32, y as f32);
            let tex = coarse.at(xf, yf) * 0.05 + fine.at(xf, yf) * 0.02;
            let c = if yf < horizon {
                let s = if (xf % seam) < 1.5 { 0.9 } else { 1.0 };
                wall.map(|v| (v * s + tex).clamp(0.0, 1.0))
            } else {
                let depth = (yf - horizon) / (hf - horizon);
                floor.map(|v| (v * (0.85 + 0.2 * depth) + tex * 1.4).clamp(0.0, 1.0))
            };
            canvas.px[y * w + x] = c;
        }
    }
    // Skirting stripe and aisle markings converging on the vanishing point.
    canvas.fill(
        &Shape::Rect((0.0, horizon - 4.0), (wf, horizon), 0.0),
        wall.map(|v| v * 0.6),
        1.0,
    );
    let vp = (wf * rng.random_range(0.4..0.6), horizon);
    let line = mix(floor, pick(rng, &[[0.95, 0.8, 0.1], [0.92, 0.92, 0.9]]), k);
    for side in [-1.0f32, 1.0] {
        let xb = vp.0 + side * wf * rng.random_range(0.15..0.35);
        let poly = Shape::Poly(vec![
            (vp.0 + side * 2.0, vp.1),
            (vp.0 + side * 3.5, vp.1),
            (xb + side * 9.0, hf),
            (xb, hf),
        ]);
        canvas.fill(&poly, line, 0.9);
    }

    // Posters and fittings on the wall.
    let posters = match clutter {
        Clutter::Low => 1,
        Clutter::Medium => 3,
        Clutter::High => 6,
    };
    for _ in 0..posters {
        let pw = rng.random_range(15.0..50.0);
        let ph = pw * rng.random_range(0.6..1.5);
        let x = rng.random_range(0.0..wf - pw);
        let y = rng.random_range(0.0..(horizon - ph).max(1.0));
        let c0 = pick(rng, &DISTRACTOR_COLORS);
        let c = mix(wall, jitter(rng, c0, 0.2), k * 0.8);
        canvas.fill(&Shape::Rect((x, y), (x + pw, y + ph), 1.0), c, 1.0);
        let band = mix(wall, [0.95, 0.95, 0.93], k * 0.8);
        canvas.fill(
            &Shape::Rect(
                (x + pw * 0.1, y + ph * 0.6),
                (x + pw * 0.9, y + ph * 0.75),
                0.0,
            ),
            band,
            1.0,
        );
    }

    // Racks.
    let racks = match clutter {
        Clutter::Low => rng.random_range(1..=2),
        Clutter::Medium => rng.random_range(3..=4),
        Clutter::High => rng.random_range(5..=7),
    };
    for _ in 0..racks {
        let rw = wf * rng.random_range(0.12..0.3);
        let x0 = rng.random_range(-rw * 0.3..wf - rw * 0.7);
        let base = horizon + rng.random_range(0.0..(hf - horizon) * 0.5);
        let rh = (base * rng.random_range(0.55..0.9)).min(base - 4.0);
        rack(
            &mut canvas,
            rng,
            RackBox {
                x0,
                base,
                w: rw,
                h: rh,
            },
            clutter,
            wall,
        );
    }

    // People.
    let people = match clutter {
        Clutter::Low => 0,
        Clutter::Medium => rng.random_range(0..=1),
        Clutter::High => rng.random_range(1..=3),
    };
    for _ in 0..people {
        let fy = rng.random_range(horizon + 10.0..hf - 2.0);
        let ph = (fy - horizon) * 1.1 + hf * 0.15;
        let fx = rng.random_range(0.0..wf);
        person(&mut canvas, rng, (fx, fy), ph, k, wall);
    }

    // Sign-like distractors.
    let distractors = match clutter {
        Clutter::Low => rng.random_range(0..=1),
        Clutter::Medium => rng.random_range(2..=4),
        Clutter::High => rng.random_range(6..=10),
    };
    for _ in 0..distractors {
        let r = rng.random_range(5.0..(hf * 0.09).max(6.0));
        let c = (rng.random_range(r..wf - r), rng.random_range(r..hf - r));
        distractor(&mut canvas, rng, c, r, wall, k);
    }
    canvas
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn variance(c: &Canvas) -> f32 {
        let n = c.px.len() as f32;
        let mean: f32 = c.px.iter().map(|p| p[0] + p[1] + p[2]).sum::<f32>() / n;
        c.px.iter()
            .map(|p| (p[0] + p[1] + p[2] - mean).powi(2))
            .sum::<f32>()
            / n
    }

    #[test]
    fn higher_clutter_gives_busier_backgrounds() {
        let mut v = [0.0f32; 3];
        for seed in 0..6 {
            for (i, clutter) in Clutter::ALL.into_iter().enumerate() {
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                v[i] += variance(&draw_world(&mut rng, 160, 100, clutter));
            }
        }
        assert!(v[0] < v[2], "low {} vs high {}", v[0], v[2]);
    }

    #[test]
    fn worlds_are_deterministic_per_seed() {
        let a = draw_world(&mut ChaCha8Rng::seed_from_u64(3), 80, 50, Clutter::High);
        let b = draw_world(&mut ChaCha8Rng::seed_from_u64(3), 80, 50, Clutter::High);
        let c = draw_world(&mut ChaCha8Rng::seed_from_u64(4), 80, 50, Clutter::High);
        assert_eq!(a.px, b.px);
        assert_ne!(a.px, c.px);
    }
}
