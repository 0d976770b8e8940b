//! Deterministic synthetic clips for testing and measuring the tracker (feature `std`).
//!
//! A textured scene (smoothed noise, random blobs and edges) with a textured "sign"
//! patch (a bordered square with its own blobs and stripes) that translates, grows (the
//! drone approaches) and shakes, with the exact ground-truth box of every frame. The
//! runtime cannot depend on `frugal-data`, so it carries this small generator itself.

use crate::geom::BBox;
use std::format;
use std::fs;
use std::io::{self, Write};
use std::path::Path;
use std::vec::Vec;

/// SplitMix64: a tiny deterministic generator.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Self(seed ^ 0x9E37_79B9_7F4A_7C15)
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }
}

/// How a clip moves.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipSpec {
    /// Frame width.
    pub width: usize,
    /// Frame height.
    pub height: usize,
    /// Number of frames.
    pub frames: usize,
    /// Seed of the scene, the sign texture and the shake.
    pub seed: u64,
    /// Sign side length in the first frame (pixels).
    pub sign_size: f32,
    /// Per-frame growth factor of the sign (approach), e.g. 1.02.
    pub growth: f32,
    /// Per-frame drift of the sign centre (pixels).
    pub velocity: (f32, f32),
    /// Largest shake offset (pixels), drawn afresh each frame.
    pub shake: f32,
    /// Largest per-pixel sensor noise (gray levels).
    pub noise: u8,
}

impl ClipSpec {
    /// A 480×270 clip of `frames` frames: a 48-px sign drifting right and down, growing
    /// 2 % per frame, shaking by up to 2 px, with ±2 levels of noise.
    pub fn standard(seed: u64, frames: usize) -> Self {
        Self {
            width: 480,
            height: 270,
            frames,
            seed,
            sign_size: 48.0,
            growth: 1.02,
            velocity: (2.5, 1.0),
            shake: 2.0,
            noise: 2,
        }
    }
}

/// Gray frames and their ground-truth sign boxes.
#[derive(Clone, Debug)]
pub struct Clip {
    /// Frame width.
    pub width: usize,
    /// Frame height.
    pub height: usize,
    /// Frames, `width · height` bytes each, stride = width.
    pub frames: Vec<Vec<u8>>,
    /// The sign's exact box in each frame.
    pub boxes: Vec<BBox>,
}

const SIGN_TEX: usize = 64;

fn blobs(img: &mut [f32], w: usize, h: usize, rng: &mut Rng, count: usize, rmin: f32, rmax: f32) {
    for _ in 0..count {
        let (cx, cy) = (rng.range(0.0, w as f32), rng.range(0.0, h as f32));
        let r = rng.range(rmin, rmax);
        let v = rng.range(-90.0, 90.0);
        let square = rng.unit() < 0.4;
        let (x0, x1) = ((cx - r).max(0.0) as usize, ((cx + r) as usize + 1).min(w));
        let (y0, y1) = ((cy - r).max(0.0) as usize, ((cy + r) as usize + 1).min(h));
        for y in y0..y1 {
            for x in x0..x1 {
                let (dx, dy) = (x as f32 - cx, y as f32 - cy);
                let inside = if square {
                    dx.abs() < r && dy.abs() < r
                } else {
                    dx * dx + dy * dy < r * r
                };
                if let Some(p) = img.get_mut(y * w + x).filter(|_| inside) {
                    *p += v;
                }
            }
        }
    }
}

/// Smoothed noise: a coarse random grid, bilinearly upsampled.
fn smooth_noise(w: usize, h: usize, cell: usize, amp: f32, rng: &mut Rng) -> Vec<f32> {
    let (gw, gh) = (w / cell + 2, h / cell + 2);
    let grid: Vec<f32> = (0..gw * gh).map(|_| rng.range(-amp, amp)).collect();
    let g = |x: usize, y: usize| grid.get(y * gw + x).copied().unwrap_or(0.0);
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let (fx, fy) = (x as f32 / cell as f32, y as f32 / cell as f32);
            let (ix, iy) = (fx as usize, fy as usize);
            let (ax, ay) = (fx - ix as f32, fy - iy as f32);
            let top = g(ix, iy) * (1.0 - ax) + g(ix + 1, iy) * ax;
            let bot = g(ix, iy + 1) * (1.0 - ax) + g(ix + 1, iy + 1) * ax;
            out.push(top * (1.0 - ay) + bot * ay);
        }
    }
    out
}

fn background(w: usize, h: usize, rng: &mut Rng) -> Vec<f32> {
    let mut img = smooth_noise(w, h, 24, 40.0, rng);
    for (p, q) in img.iter_mut().zip(smooth_noise(w, h, 4, 18.0, rng)) {
        *p += 110.0 + q;
    }
    blobs(&mut img, w, h, rng, w * h / 900, 3.0, 14.0);
    // A few long straight edges (shelves, walls).
    for _ in 0..6 {
        let vertical = rng.unit() < 0.5;
        let pos = rng.range(0.0, if vertical { w } else { h } as f32) as usize;
        let v = rng.range(-40.0, 40.0);
        for y in 0..h {
            for x in 0..w {
                let side = if vertical { x > pos } else { y > pos };
                if let Some(p) = img.get_mut(y * w + x).filter(|_| side) {
                    *p += v * 0.3;
                }
            }
        }
    }
    img
}

fn sign_texture(rng: &mut Rng) -> Vec<f32> {
    let n = SIGN_TEX;
    let mut tex = smooth_noise(n, n, 8, 30.0, rng);
    for (i, p) in tex.iter_mut().enumerate() {
        let (x, y) = ((i % n) as f32, (i / n) as f32);
        let border = x < 6.0 || y < 6.0 || x >= n as f32 - 6.0 || y >= n as f32 - 6.0;
        let stripe = (((x + 2.0 * y) / 7.0) as usize).is_multiple_of(2);
        *p += if border {
            40.0
        } else if stripe {
            190.0
        } else {
            150.0
        };
    }
    blobs(&mut tex, n, n, rng, 14, 2.0, 7.0);
    tex
}

fn bilinear(tex: &[f32], n: usize, u: f32, v: f32) -> f32 {
    let u = u.clamp(0.0, n as f32 - 1.001);
    let v = v.clamp(0.0, n as f32 - 1.001);
    let (iu, iv) = (u as usize, v as usize);
    let (au, av) = (u - iu as f32, v - iv as f32);
    let t = |x: usize, y: usize| tex.get(y * n + x).copied().unwrap_or(0.0);
    let top = t(iu, iv) * (1.0 - au) + t(iu + 1, iv) * au;
    let bot = t(iu, iv + 1) * (1.0 - au) + t(iu + 1, iv + 1) * au;
    top * (1.0 - av) + bot * av
}

/// Renders a clip.
pub fn make_clip(spec: &ClipSpec) -> Clip {
    let (w, h) = (spec.width, spec.height);
    let mut rng = Rng::new(spec.seed);
    let bg = background(w, h, &mut rng);
    let tex = sign_texture(&mut rng);
    let mut frames = Vec::with_capacity(spec.frames);
    let mut boxes = Vec::with_capacity(spec.frames);
    let (mut cx, mut cy) = (w as f32 * 0.3, h as f32 * 0.4);
    let mut size = spec.sign_size;
    for _ in 0..spec.frames {
        let sx = rng.range(-spec.shake, spec.shake);
        let sy = rng.range(-spec.shake, spec.shake);
        let b = BBox::from_xywh(cx + sx - size / 2.0, cy + sy - size / 2.0, size, size);
        let mut frame = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                let base = if px >= b.x1 && px < b.x2 && py >= b.y1 && py < b.y2 {
                    let u = (px - b.x1) / size * SIGN_TEX as f32 - 0.5;
                    let v = (py - b.y1) / size * SIGN_TEX as f32 - 0.5;
                    bilinear(&tex, SIGN_TEX, u, v)
                } else {
                    bg.get(y * w + x).copied().unwrap_or(0.0)
                };
                let n = if spec.noise > 0 {
                    rng.range(-f32::from(spec.noise), f32::from(spec.noise))
                } else {
                    0.0
                };
                frame.push((base + n).round().clamp(0.0, 255.0) as u8);
            }
        }
        frames.push(frame);
        boxes.push(b);
        cx += spec.velocity.0;
        cy += spec.velocity.1;
        size *= spec.growth;
    }
    Clip {
        width: w,
        height: h,
        frames,
        boxes,
    }
}

impl Clip {
    /// Writes `frame_0000.pgm`, … (binary P5) and `boxes.csv` (`frame,x1,y1,x2,y2`) into
    /// `dir`, each through a temporary file renamed into place.
    pub fn write_pgm_dir(&self, dir: &Path) -> io::Result<()> {
        fs::create_dir_all(dir)?;
        let put = |name: &str, bytes: &[u8]| -> io::Result<()> {
            let tmp = dir.join(format!(".{name}.tmp"));
            fs::File::create(&tmp)?.write_all(bytes)?;
            fs::rename(&tmp, dir.join(name))
        };
        for (i, f) in self.frames.iter().enumerate() {
            let mut bytes = format!("P5\n{} {}\n255\n", self.width, self.height).into_bytes();
            bytes.extend_from_slice(f);
            put(&format!("frame_{i:04}.pgm"), &bytes)?;
        }
        let mut csv = std::string::String::from("frame,x1,y1,x2,y2\n");
        for (i, b) in self.boxes.iter().enumerate() {
            csv.push_str(&format!("{i},{},{},{},{}\n", b.x1, b.y1, b.x2, b.y2));
        }
        put("boxes.csv", csv.as_bytes())
    }
}
