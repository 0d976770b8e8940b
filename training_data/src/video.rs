//! One synthetic video: a camera drifting, zooming and shaking through a warehouse
//! world while signs approach it and pass out of view.
//!
//! Geometry (2.5-D): each sign "event" has a time `τ ∈ [0, 1]` along its approach. Its
//! size grows like `1 / distance` from a small start size to a large end size, and its
//! centre moves outward from the focus of expansion in proportion to its size, so it
//! leaves the frame near the end. Several "lanes" (1..=`max_signs`) hold events in
//! different directions, so up to three signs are in view at once, with gaps.
//!
//! Boxes: the sign's outline coverage (its alpha), times `1 -` the coverage of every
//! nearer sign (occlusion), blurred with the frame's motion-blur kernel, is the
//! sign's visible mask; the box is the tight pixel box of mask ≥ [`MASK_THRESHOLD`],
//! clipped to the frame. **Drop rule:** an object is annotated only when its visible
//! box is at least `min_visible_px` wide and high and its visible (unblurred,
//! un-occluded, in-frame) area is at least `min_visible_fraction` of the whole sign's
//! area; signs below that are still drawn (like partly visible signs in real footage).
//!
//! Over 600 lines with its unit tests (the last 250).
use crate::raster::{Canvas, Shape, coverage};
use crate::scene::draw_world;
use crate::sign::{SignStyle, paint_sign, to_u8};
use crate::{BBox, GenConfig, Light, Object, Sign, VideoPlan};
use rand::{Rng, SeedableRng};
use rand_chacha::{ChaCha8Rng, ChaCha20Rng};

/// A pixel belongs to a sign's box when the sign's visible mask is at least this.
pub const MASK_THRESHOLD: f32 = 0.25;

/// The seed of video `id` under global seed `seed`: the first word of ChaCha20
/// seeded with `seed`, on stream `id`.
pub fn video_seed(seed: u64, id: u32) -> u64 {
    let mut rng = ChaCha20Rng::seed_from_u64(seed);
    rng.set_stream(u64::from(id));
    rng.random()
}

#[derive(Clone, Debug)]
struct SignEvent {
    sign: Sign,
    start: f32,
    dur: f32,
    dir: (f32, f32),
    lateral: f32,
    aspect: f32,
    min_size: f32,
    max_size: f32,
    style: SignStyle,
}

#[derive(Clone, Debug)]
struct LightParams {
    gain: f32,
    tint: [f32; 3],
    contrast: f32,
    vignette: f32,
    noise: f32,
    flicker: f32,
}

/// What to draw: the full photograph, or (for checking boxes) the signs alone over a
/// flat background without lighting and noise.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderOptions {
    /// Replace the warehouse by this flat colour.
    pub flat_background: Option<[f32; 3]>,
    /// Skip lighting, vignetting and sensor noise.
    pub no_photometric: bool,
}

/// One rendered frame and its annotations.
#[derive(Clone, Debug)]
pub struct RenderedFrame {
    /// The pixels.
    pub rgb: image::RgbImage,
    /// The annotated signs (after the drop rule).
    pub objects: Vec<Object>,
}

/// Everything needed to render any frame of one video, independently of the others.
pub struct Video {
    width: usize,
    height: usize,
    frames: u32,
    seed: u64,
    world: Canvas,
    cam0: (f32, f32),
    /// Frames over which the camera sweeps its pan and zoom (then back, and so on).
    pace: f32,
    cam_v: (f32, f32),
    zoom_rate: f32,
    shake: [(f32, f32, f32); 4],
    jitter: Vec<(f32, f32)>,
    exposure: f32,
    max_blur: f32,
    foe: (f32, f32),
    events: Vec<SignEvent>,
    light: LightParams,
    min_visible_px: f32,
    min_visible_fraction: f32,
}

/// How far into its sweep a camera paced over `pace` frames is at frame `t`, in frames,
/// and which way it moves (1 out, −1 back): `t` itself up to `pace`, then back to 0 at
/// `2 · pace`, out again, and so on (a triangle wave, so a video longer than its pace
/// stays within the pan and zoom range it drew).
fn sweep(t: f32, pace: f32) -> (f32, f32) {
    if t <= pace || pace <= 0.0 {
        return (t, 1.0);
    }
    let phase = t % (2.0 * pace);
    if phase <= pace {
        (phase, 1.0)
    } else {
        (2.0 * pace - phase, -1.0)
    }
}

impl Video {
    /// Plan video `plan` of `config`, whose seed is `seed`.
    pub fn new(config: &GenConfig, plan: &VideoPlan, seed: u64) -> Video {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (w, h) = (config.width as usize, config.height as usize);
        let (wf, hf) = (w as f32, h as f32);
        let ww = (wf * 1.7).ceil() as usize;
        let wh = (hf * 1.5).ceil() as usize;
        let world = draw_world(&mut rng, ww, wh, plan.clutter);
        let t = plan.frames.max(1) as f32;
        // the motion's pace: the video's length unless the config sets one
        let pace = match config.pace_frames {
            0 => t,
            p => p as f32,
        };

        let (xmin, xmax) = (wf * 0.5 + 2.0, ww as f32 - wf * 0.5 - 2.0);
        let (ymin, ymax) = (hf * 0.5 + 2.0, wh as f32 - hf * 0.5 - 2.0);
        let cx0 = rng.random_range(xmin..xmax);
        let cy0 = rng.random_range(ymin..ymax);
        let cx1 = (cx0 + rng.random_range(-0.35..0.35) * wf).clamp(xmin, xmax);
        let cy1 = (cy0 + rng.random_range(-0.1..0.1) * hf).clamp(ymin, ymax);
        let amp = rng.random_range(0.4..2.0) * wf / 480.0;
        let shake = std::array::from_fn(|i| {
            (
                amp / (1.0 + i as f32),
                rng.random_range(0.15..1.2),
                rng.random_range(0.0..std::f32::consts::TAU),
            )
        });
        let jitter = (0..plan.frames)
            .map(|_| {
                (
                    rng.random_range(-0.5..0.5) * amp,
                    rng.random_range(-0.5..0.5) * amp,
                )
            })
            .collect();
        let foe = (
            wf * (0.5 + rng.random_range(-0.1..0.1)),
            hf * (0.5 + rng.random_range(-0.1..0.1)),
        );

        // Sign events, lane by lane.
        let lanes = rng.random_range(1..=config.max_signs) as usize;
        let a0 = rng.random_range(0.0..std::f32::consts::TAU);
        let mut events = Vec::new();
        for lane in 0..lanes {
            let a = a0
                + lane as f32 * std::f32::consts::TAU / lanes as f32
                + rng.random_range(-0.3..0.3);
            let dur_of = |rng: &mut ChaCha8Rng| pace.max(12.0) * rng.random_range(0.6..1.2);
            let mut dur = dur_of(&mut rng);
            let mut start = -rng.random_range(0.0..dur * 0.9);
            while start < t {
                let gap_scale = if lane == 0 {
                    config.empty_fraction / (1.0 - config.empty_fraction)
                } else {
                    0.6
                };
                let dir_a = a + rng.random_range(-0.25..0.25);
                // Classes cycle through every sign (step 3 is coprime with 10), from an
                // offset that differs per video, so even a split of a few videos sees
                // every class.
                let class = (plan.id as usize * 7 + events.len() * 3) % Sign::ALL.len();
                events.push(SignEvent {
                    sign: Sign::ALL[class],
                    start,
                    dur,
                    dir: (dir_a.cos(), dir_a.sin() * 0.8),
                    lateral: rng.random_range(-0.3..0.3),
                    aspect: rng.random_range(0.78..1.0),
                    min_size: config.min_sign_px * rng.random_range(1.0..1.5),
                    max_size: config.max_sign_px * rng.random_range(0.65..1.0),
                    style: SignStyle {
                        fade: rng.random_range(0.0..0.5),
                        brightness: rng.random_range(0.8..1.05),
                    },
                });
                start += dur + dur * gap_scale * rng.random_range(0.5..1.5);
                dur = dur_of(&mut rng);
            }
        }

        let light = match plan.light {
            Light::Normal => LightParams {
                gain: rng.random_range(0.92..1.06),
                tint: [
                    1.0 + rng.random_range(-0.03..0.03),
                    1.0,
                    1.0 + rng.random_range(-0.03..0.03),
                ],
                contrast: 1.0,
                vignette: rng.random_range(0.05..0.2),
                noise: 0.004,
                flicker: 0.01,
            },
            Light::Low => {
                let warm = rng.random_bool(0.5);
                LightParams {
                    gain: rng.random_range(0.28..0.42),
                    tint: if warm {
                        [1.08, 0.95, 0.75]
                    } else {
                        [0.85, 0.95, 1.1]
                    },
                    contrast: rng.random_range(0.65..0.8),
                    vignette: rng.random_range(0.25..0.45),
                    noise: 0.018,
                    flicker: 0.04,
                }
            }
        };
        Video {
            width: w,
            height: h,
            frames: plan.frames,
            seed,
            world,
            cam0: (cx0, cy0),
            pace,
            cam_v: ((cx1 - cx0) / pace, (cy1 - cy0) / pace),
            zoom_rate: rng.random_range(0.1..0.3) / pace,
            shake,
            jitter,
            exposure: rng.random_range(0.5..0.9),
            max_blur: config.max_motion_blur_px,
            foe,
            events,
            light,
            min_visible_px: config.min_visible_px,
            min_visible_fraction: config.min_visible_fraction,
        }
    }

    /// Number of frames.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    fn shake_at(&self, t: f32) -> (f32, f32) {
        let mut s = (0.0, 0.0);
        for (i, &(a, f, p)) in self.shake.iter().enumerate() {
            let v = a * (f * t + p).sin();
            if i % 2 == 0 { s.0 += v } else { s.1 += v * 0.8 }
        }
        let j = self.jitter.get(t as usize).copied().unwrap_or((0.0, 0.0));
        (s.0 + j.0, s.1 + j.1)
    }

    /// Render frame `index`.
    pub fn frame(&self, index: u32, opts: &RenderOptions) -> RenderedFrame {
        let (w, h) = (self.width, self.height);
        let (wf, hf) = (w as f32, h as f32);
        let t = index as f32;
        let (swept, way) = sweep(t, self.pace);
        let zoom = 1.0 + self.zoom_rate * swept;
        let cam = (
            self.cam0.0 + self.cam_v.0 * swept,
            self.cam0.1 + self.cam_v.1 * swept,
        );
        let shake = self.shake_at(t);

        // Background: a window of the world, resampled bilinearly.
        let mut canvas = match opts.flat_background {
            Some(c) => Canvas::new(w, h, c),
            None => {
                let mut c = Canvas::new(w, h, [0.0; 3]);
                for y in 0..h {
                    let wy = cam.1 + (y as f32 + 0.5 - hf * 0.5 - shake.1) / zoom - 0.5;
                    for x in 0..w {
                        let wx = cam.0 + (x as f32 + 0.5 - wf * 0.5 - shake.0) / zoom - 0.5;
                        c.px[y * w + x] = bilinear(&self.world, wx, wy);
                    }
                }
                c
            }
        };

        // Signs in view, far (small) to near (large).
        let mut visible: Vec<(&SignEvent, f32, (f32, f32))> = Vec::new();
        for e in &self.events {
            let tau = (t - e.start) / e.dur;
            if !(0.0..=1.0).contains(&tau) {
                continue;
            }
            let size = e.min_size / (1.0 - tau * (1.0 - e.min_size / e.max_size));
            let reach_x = if e.dir.0.abs() > 1e-3 {
                wf * 0.5 / e.dir.0.abs()
            } else {
                f32::INFINITY
            };
            let reach_y = if e.dir.1.abs() > 1e-3 {
                hf * 0.5 / e.dir.1.abs()
            } else {
                f32::INFINITY
            };
            let reach = reach_x.min(reach_y) + 0.15 * e.max_size;
            let k = size / e.max_size;
            let perp = (-e.dir.1, e.dir.0);
            let c = (
                self.foe.0 + e.dir.0 * reach * k + perp.0 * e.lateral * size + shake.0,
                self.foe.1 + e.dir.1 * reach * k + perp.1 * e.lateral * size + shake.1,
            );
            let (hw, hh) = (size * e.aspect * 0.5, size * 0.5);
            if c.0 + hw < 0.0 || c.0 - hw > wf || c.1 + hh < 0.0 || c.1 - hh > hf {
                continue;
            }
            visible.push((e, size, c));
        }
        visible.sort_by(|a, b| a.1.total_cmp(&b.1));
        let mut outlines: Vec<(Sign, Shape, f32)> = Vec::new();
        for &(e, size, c) in &visible {
            let style = if opts.no_photometric {
                SignStyle::default()
            } else {
                e.style
            };
            let outline = paint_sign(
                &mut canvas,
                e.sign,
                c,
                size * e.aspect * 0.5,
                size * 0.5,
                &style,
            );
            let full_area = full_area(&outline);
            outlines.push((e.sign, outline, full_area));
        }

        // Motion blur from the camera's screen-space velocity.
        let v = {
            let s0 = self.shake_at((t - 1.0).max(0.0));
            (
                -self.cam_v.0 * way * zoom + (shake.0 - s0.0),
                -self.cam_v.1 * way * zoom + (shake.1 - s0.1),
            )
        };
        let mut blur = (v.0 * self.exposure, v.1 * self.exposure);
        let len = (blur.0 * blur.0 + blur.1 * blur.1).sqrt();
        if len > self.max_blur {
            blur = (blur.0 * self.max_blur / len, blur.1 * self.max_blur / len);
        }
        let taps = blur_taps(blur);
        canvas.px = motion_blur(&canvas.px, w, h, &taps);

        // Boxes from the visible masks.
        let masks: Vec<Vec<f32>> = outlines.iter().map(|(_, s, _)| coverage(s, w, h)).collect();
        let mut objects = Vec::new();
        for (i, (sign, _, full)) in outlines.iter().enumerate() {
            let mut vis = masks[i].clone();
            for nearer in &masks[i + 1..] {
                for (v, n) in vis.iter_mut().zip(nearer) {
                    *v *= 1.0 - n;
                }
            }
            let area: f32 = vis.iter().sum();
            let blurred = motion_blur(&vis, w, h, &taps);
            let Some(bbox) = mask_box(&blurred, w, h, MASK_THRESHOLD) else {
                continue;
            };
            if bbox.width() >= self.min_visible_px
                && bbox.height() >= self.min_visible_px
                && area >= self.min_visible_fraction * full
            {
                objects.push(Object {
                    class: sign.id(),
                    bbox,
                });
            }
        }
        objects.sort_by(|a, b| {
            (a.bbox.x1, a.bbox.y1, a.class)
                .partial_cmp(&(b.bbox.x1, b.bbox.y1, b.class))
                .unwrap_or(std::cmp::Ordering::Equal)
        });

        let rgb = if opts.no_photometric {
            image::RgbImage::from_fn(w as u32, h as u32, |x, y| {
                let p = canvas.px[y as usize * w + x as usize];
                image::Rgb([to_u8(p[0]), to_u8(p[1]), to_u8(p[2])])
            })
        } else {
            self.photometric(&canvas, index)
        };
        RenderedFrame { rgb, objects }
    }

    /// Lighting, vignetting and sensor noise (seeded per frame).
    fn photometric(&self, canvas: &Canvas, index: u32) -> image::RgbImage {
        let (w, h) = (self.width, self.height);
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        rng.set_stream(u64::from(index) + 1);
        let l = &self.light;
        let gain = l.gain * (1.0 + rng.random_range(-1.0..1.0) * l.flicker);
        let (cx, cy) = (w as f32 * 0.5, h as f32 * 0.5);
        let r2max = cx * cx + cy * cy;
        let mut out = image::RgbImage::new(w as u32, h as u32);
        let raw: &mut [u8] = &mut out;
        for y in 0..h {
            for x in 0..w {
                let dx = x as f32 + 0.5 - cx;
                let dy = y as f32 + 0.5 - cy;
                let vig = 1.0 - l.vignette * (dx * dx + dy * dy) / r2max;
                let p = canvas.px[y * w + x];
                let bits: u32 = rng.random();
                for k in 0..3 {
                    let b = (bits >> (k * 10)) & 0x3ff;
                    let b2 = (bits >> (k * 10 + 5)) & 0x1f;
                    // Triangular noise from two uniforms, variance-matched.
                    let n = ((b & 0x1f) as f32 + b2 as f32 - 31.0) / 31.0 * 2.45 * l.noise;
                    let v = ((p[k] - 0.5) * l.contrast + 0.5) * gain * l.tint[k] * vig + n;
                    raw[(y * w + x) * 3 + k] = to_u8(v);
                }
            }
        }
        out
    }
}

/// Area of a shape, from its coverage on a grid covering its bounds.
fn full_area(shape: &Shape) -> f32 {
    let (lo, hi) = shape.bounds();
    let (ox, oy) = (lo.0.floor() - 1.0, lo.1.floor() - 1.0);
    let local = shape.mapped(1.0, 1.0, -ox, -oy);
    let w = (hi.0 - ox).ceil() as usize + 2;
    let h = (hi.1 - oy).ceil() as usize + 2;
    coverage(&local, w, h).iter().sum()
}

fn bilinear(c: &Canvas, x: f32, y: f32) -> [f32; 3] {
    let x = x.clamp(0.0, (c.w - 1) as f32);
    let y = y.clamp(0.0, (c.h - 1) as f32);
    let (x0, y0) = (x as usize, y as usize);
    let (x1, y1) = ((x0 + 1).min(c.w - 1), (y0 + 1).min(c.h - 1));
    let (tx, ty) = (x - x0 as f32, y - y0 as f32);
    let p = |a: usize, b: usize| c.px[b * c.w + a];
    let (a, b, cc, d) = (p(x0, y0), p(x1, y0), p(x0, y1), p(x1, y1));
    std::array::from_fn(|k| {
        let top = a[k] + (b[k] - a[k]) * tx;
        let bot = cc[k] + (d[k] - cc[k]) * tx;
        top + (bot - top) * ty
    })
}

/// Integer pixel offsets along the blur vector, centred on 0.
fn blur_taps(v: (f32, f32)) -> Vec<(i32, i32)> {
    let len = (v.0 * v.0 + v.1 * v.1).sqrt();
    if len < 0.75 {
        return vec![(0, 0)];
    }
    let n = len.ceil() as usize + 1;
    (0..n)
        .map(|k| {
            let s = k as f32 / (n - 1) as f32 - 0.5;
            ((v.0 * s).round() as i32, (v.1 * s).round() as i32)
        })
        .collect()
}

/// Average of `src` over the tap offsets, clamping at the borders.
fn motion_blur<T: Blend>(src: &[T], w: usize, h: usize, taps: &[(i32, i32)]) -> Vec<T> {
    if taps.len() <= 1 {
        return src.to_vec();
    }
    let inv = 1.0 / taps.len() as f32;
    let mut out = Vec::with_capacity(src.len());
    for y in 0..h as i32 {
        for x in 0..w as i32 {
            let mut acc = T::ZERO;
            for &(dx, dy) in taps {
                let sx = (x + dx).clamp(0, w as i32 - 1) as usize;
                let sy = (y + dy).clamp(0, h as i32 - 1) as usize;
                acc = acc.add(src[sy * w + sx]);
            }
            out.push(acc.scale(inv));
        }
    }
    out
}

trait Blend: Copy {
    const ZERO: Self;
    fn add(self, o: Self) -> Self;
    fn scale(self, k: f32) -> Self;
}

impl Blend for f32 {
    const ZERO: Self = 0.0;
    fn add(self, o: Self) -> Self {
        self + o
    }
    fn scale(self, k: f32) -> Self {
        self * k
    }
}

impl Blend for [f32; 3] {
    const ZERO: Self = [0.0; 3];
    fn add(self, o: Self) -> Self {
        [self[0] + o[0], self[1] + o[1], self[2] + o[2]]
    }
    fn scale(self, k: f32) -> Self {
        self.map(|v| v * k)
    }
}

/// The tight pixel box of `mask >= thr` (exclusive right/bottom edges).
pub fn mask_box(mask: &[f32], w: usize, h: usize, thr: f32) -> Option<BBox> {
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for y in 0..h {
        for x in 0..w {
            if mask[y * w + x] >= thr {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x + 1);
                y1 = y1.max(y + 1);
            }
        }
    }
    (x1 > x0 && y1 > y0).then(|| BBox::new(x0 as f32, y0 as f32, x1 as f32, y1 as f32))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Clutter, Split};

    fn plan(clutter: Clutter, light: Light) -> VideoPlan {
        VideoPlan {
            id: 0,
            clutter,
            light,
            split: Split::Train,
            frames: single_sign_config().frames_per_video,
            first_frame: 0,
        }
    }

    fn single_sign_config() -> GenConfig {
        GenConfig {
            frames_per_video: 24,
            max_signs: 1,
            empty_fraction: 0.2,
            max_motion_blur_px: 4.0,
            ..GenConfig::tiny()
        }
    }

    /// Alpha of everything drawn over the background, recovered from two renders over
    /// black and over white: `white - black = (1 - alpha) * 255`.
    fn alpha_map(v: &Video, index: u32) -> (Vec<f32>, usize, usize) {
        let black = v.frame(
            index,
            &RenderOptions {
                flat_background: Some([0.0; 3]),
                no_photometric: true,
            },
        );
        let white = v.frame(
            index,
            &RenderOptions {
                flat_background: Some([1.0; 3]),
                no_photometric: true,
            },
        );
        let (w, h) = (black.rgb.width() as usize, black.rgb.height() as usize);
        let alpha = black
            .rgb
            .pixels()
            .zip(white.rgb.pixels())
            .map(|(b, wt)| {
                let d: f32 = (0..3)
                    .map(|k| f32::from(wt[k]) - f32::from(b[k]))
                    .sum::<f32>()
                    / 3.0;
                1.0 - d / 255.0
            })
            .collect();
        (alpha, w, h)
    }

    #[test]
    fn boxes_are_tight_around_the_rendered_sign_pixels() {
        let config = single_sign_config();
        let (mut checked, mut dropped) = (0, 0);
        for seed in 0..6u64 {
            let v = Video::new(&config, &plan(Clutter::Medium, Light::Normal), seed);
            for index in 0..config.frames_per_video {
                let (alpha, w, h) = alpha_map(&v, index);
                let objects = v.frame(index, &RenderOptions::default()).objects;
                assert!(objects.len() <= 1);
                let drawn = mask_box(&alpha, w, h, MASK_THRESHOLD);
                match (objects.first(), drawn) {
                    (Some(o), Some(d)) => {
                        for (a, b) in [
                            (o.bbox.x1, d.x1),
                            (o.bbox.y1, d.y1),
                            (o.bbox.x2, d.x2),
                            (o.bbox.y2, d.y2),
                        ] {
                            assert!(
                                (a - b).abs() <= 2.0,
                                "seed {seed} frame {index}: box {:?} vs pixels {d:?}",
                                o.bbox
                            );
                        }
                        checked += 1;
                    }
                    (Some(o), None) => panic!(
                        "seed {seed} frame {index}: box {:?} but nothing drawn",
                        o.bbox
                    ),
                    (None, Some(d)) => {
                        // Only the drop rule may hide a drawn sign: small or cut by the border.
                        let small = d.width() < config.min_visible_px + 2.0
                            || d.height() < config.min_visible_px + 2.0;
                        let cut =
                            d.x1 <= 0.0 || d.y1 <= 0.0 || d.x2 >= w as f32 || d.y2 >= h as f32;
                        assert!(
                            small || cut,
                            "seed {seed} frame {index}: sign at {d:?} not annotated"
                        );
                        dropped += 1;
                    }
                    (None, None) => {}
                }
            }
        }
        assert!(checked > 60, "checked {checked} boxes ({dropped} dropped)");
    }

    #[test]
    fn signs_approach_the_camera_over_a_clip() {
        let config = single_sign_config();
        let mut grew = 0;
        for seed in 0..6u64 {
            let v = Video::new(&config, &plan(Clutter::Low, Light::Normal), seed);
            let sizes: Vec<f32> = (0..config.frames_per_video)
                .filter_map(|i| {
                    v.frame(i, &RenderOptions::default())
                        .objects
                        .first()
                        .map(|o| o.bbox.height())
                })
                .collect();
            if let (Some(first), Some(max)) =
                (sizes.first(), sizes.iter().copied().reduce(f32::max))
            {
                grew += usize::from(max >= first * 1.5);
            }
        }
        assert!(grew >= 3, "signs grew in {grew} of 6 videos");
    }

    #[test]
    fn frames_are_deterministic_per_seed_and_differ_between_seeds() {
        let config = GenConfig::tiny();
        let p = plan(Clutter::High, Light::Low);
        let a = Video::new(&config, &p, 11).frame(2, &RenderOptions::default());
        let b = Video::new(&config, &p, 11).frame(2, &RenderOptions::default());
        let c = Video::new(&config, &p, 12).frame(2, &RenderOptions::default());
        assert_eq!(a.rgb, b.rgb);
        assert_eq!(a.objects, b.objects);
        assert_ne!(a.rgb, c.rgb);
        assert_ne!(video_seed(1, 0), video_seed(1, 1));
        assert_ne!(video_seed(1, 0), video_seed(2, 0));
    }

    #[test]
    fn low_light_is_darker_and_noisier() {
        let config = GenConfig::tiny();
        let mean = |img: &image::RgbImage| {
            img.as_raw().iter().map(|&v| f64::from(v)).sum::<f64>() / img.as_raw().len() as f64
        };
        let (mut normal, mut low) = (0.0, 0.0);
        for seed in 0..4 {
            normal += mean(
                &Video::new(&config, &plan(Clutter::Medium, Light::Normal), seed)
                    .frame(0, &RenderOptions::default())
                    .rgb,
            );
            low += mean(
                &Video::new(&config, &plan(Clutter::Medium, Light::Low), seed)
                    .frame(0, &RenderOptions::default())
                    .rgb,
            );
        }
        assert!(low < normal * 0.6, "low {low} vs normal {normal}");
    }

    #[test]
    fn blur_taps_follow_the_motion() {
        assert_eq!(blur_taps((0.2, 0.1)), vec![(0, 0)]);
        let t = blur_taps((4.0, 0.0));
        assert_eq!(t.len(), 5);
        assert_eq!(t.first(), Some(&(-2, 0)));
        assert_eq!(t.last(), Some(&(2, 0)));
        let img = vec![0.0, 0.0, 1.0, 0.0, 0.0];
        let b = motion_blur(&img, 5, 1, &[(-1, 0), (0, 0), (1, 0)]);
        assert!((b[1] - 1.0 / 3.0).abs() < 1e-6 && (b[2] - 1.0 / 3.0).abs() < 1e-6 && b[0] == 0.0);
    }

    #[test]
    fn a_sweep_runs_out_and_back_within_its_pace() {
        assert_eq!(sweep(0.0, 24.0), (0.0, 1.0));
        assert_eq!(sweep(17.0, 24.0), (17.0, 1.0));
        assert_eq!(sweep(24.0, 24.0), (24.0, 1.0));
        assert_eq!(sweep(30.0, 24.0), (18.0, -1.0));
        assert_eq!(sweep(48.0, 24.0), (0.0, 1.0));
        assert_eq!(sweep(50.0, 24.0), (2.0, 1.0));
        for i in 0..500 {
            let (s, way) = sweep(i as f32 * 0.37, 24.0);
            assert!(
                (0.0..=24.0).contains(&s) && way.abs() == 1.0,
                "{i}: {s} {way}"
            );
        }
    }

    /// Pacing a video over its own length draws the very same video, and a config that
    /// leaves the pace unset keeps the hash it had before the pace existed.
    #[test]
    fn a_pace_of_the_video_s_own_length_draws_the_same_video() {
        let config = single_sign_config();
        let paced = GenConfig {
            pace_frames: config.frames_per_video,
            ..config.clone()
        };
        let p = plan(Clutter::High, Light::Low);
        for seed in 0..2u64 {
            let (a, b) = (Video::new(&config, &p, seed), Video::new(&paced, &p, seed));
            for index in 0..config.frames_per_video {
                let (fa, fb) = (
                    a.frame(index, &RenderOptions::default()),
                    b.frame(index, &RenderOptions::default()),
                );
                assert_eq!(fa.rgb, fb.rgb, "seed {seed} frame {index}");
                assert_eq!(fa.objects, fb.objects, "seed {seed} frame {index}");
            }
        }
        let json = serde_json::to_string(&GenConfig::default()).expect("json");
        assert!(!json.contains("pace_frames"), "{json}");
        assert_ne!(config.hash(), paced.hash());
    }

    /// Per-frame motion of the one sign in view (the change of its box's height plus
    /// its centre's shift, in pixels, between consecutive frames that both show one),
    /// the median over `seeds` videos of `frames` frames paced over `pace`.
    fn median_motion(frames: u32, pace: u32, seeds: u64) -> (f32, usize) {
        let config = GenConfig {
            frames_per_video: frames,
            pace_frames: pace,
            ..single_sign_config()
        };
        let p = VideoPlan {
            frames,
            ..plan(Clutter::Low, Light::Normal)
        };
        let mut steps = Vec::new();
        let mut appearances = 0;
        for seed in 0..seeds {
            let v = Video::new(&config, &p, seed);
            let mut last: Option<BBox> = None;
            for index in 0..frames {
                let now = v
                    .frame(index, &RenderOptions::default())
                    .objects
                    .first()
                    .map(|o| o.bbox);
                match (last, now) {
                    (Some(a), Some(b)) => {
                        let ((ax, ay), (bx, by)) = (a.center(), b.center());
                        steps.push((b.height() - a.height()).abs() + (bx - ax).hypot(by - ay));
                    }
                    (None, Some(_)) => appearances += 1,
                    _ => {}
                }
                last = now;
            }
        }
        steps.sort_by(f32::total_cmp);
        (
            steps.get(steps.len() / 2).copied().unwrap_or(f32::NAN),
            appearances,
        )
    }

    /// A video four times as long moves less than half as fast per frame when paced
    /// over its own length, and about as fast as a short one, with more than twice the
    /// approaches, when paced over the short one's length.
    #[test]
    fn a_long_video_at_a_short_pace_moves_as_fast_as_a_short_one() {
        let (short, short_seen) = median_motion(24, 0, 6);
        let (slow, _) = median_motion(96, 0, 6);
        let (paced, paced_seen) = median_motion(96, 24, 6);
        assert!(short > 0.5, "short {short}");
        assert!(slow < 0.5 * short, "slow {slow} against short {short}");
        assert!(
            paced > 0.6 * short && paced < 1.6 * short,
            "paced {paced} against short {short}"
        );
        assert!(
            paced_seen > 2 * short_seen,
            "appearances {paced_seen} against {short_seen}"
        );
    }
}

#[cfg(test)]
mod arrow_tests {
    use super::*;
    use crate::{Clutter, Split};

    /// In rendered frames (not just sprites), a box labelled turn_left holds an arrow
    /// whose head (the wider white part) is on the left, and turn_right on the right:
    /// labels are never swapped and nothing flips the image.
    #[test]
    fn turn_labels_match_the_arrow_direction_in_frames() {
        let config = GenConfig {
            frames_per_video: 30,
            max_motion_blur_px: 0.0,
            ..GenConfig::tiny()
        };
        let flat = RenderOptions {
            flat_background: Some([0.0; 3]),
            no_photometric: true,
        };
        let mut checked = [0usize; 2];
        for id in 0..24u32 {
            let plan = VideoPlan {
                id,
                clutter: Clutter::Low,
                light: Light::Normal,
                split: Split::Train,
                frames: config.frames_per_video,
                first_frame: 0,
            };
            let v = Video::new(&config, &plan, u64::from(id) + 100);
            for index in 0..config.frames_per_video {
                let f = v.frame(index, &flat);
                for o in &f.objects {
                    let left = o.class == Sign::TurnLeft.id();
                    if !(left || o.class == Sign::TurnRight.id()) {
                        continue;
                    }
                    let b = o.bbox;
                    let inside = b.x1 > 0.0 && b.y1 > 0.0 && b.x2 < 192.0 && b.y2 < 108.0;
                    if !inside || b.width() < 20.0 {
                        continue;
                    }
                    // White pixels off the shaft's band and inside the rim belong to the
                    // arrow head: their mean horizontal position gives the direction.
                    let (cx, cy) = b.center();
                    let (hw, hh) = (b.width() * 0.5, b.height() * 0.5);
                    let (mut sum, mut n, mut weight) = (0.0f32, 0, 0.0f32);
                    for y in b.y1 as u32..b.y2 as u32 {
                        for x in b.x1 as u32..b.x2 as u32 {
                            let u = (x as f32 + 0.5 - cx) / hw;
                            let w = (y as f32 + 0.5 - cy) / hh;
                            // Red is ~0 on the blue field and high on the white arrow.
                            let red = (f32::from(f.rgb.get_pixel(x, y)[0]) / 255.0 - 0.2).max(0.0);
                            if w.abs() > 0.22 && u * u + w * w < 0.75 * 0.75 {
                                sum += u * red;
                                n += 1;
                                weight += red;
                            }
                        }
                    }
                    assert!(n > 0 && weight > 1.0, "no arrow head found in {b:?}");
                    let mean = sum / weight;
                    if left {
                        assert!(mean < -0.1, "turn_left box {b:?}: head at {mean}");
                    } else {
                        assert!(mean > 0.1, "turn_right box {b:?}: head at {mean}");
                    }
                    checked[usize::from(!left)] += 1;
                }
            }
        }
        assert!(checked[0] >= 5 && checked[1] >= 5, "checked {checked:?}");
    }
}
