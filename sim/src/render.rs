//! The first-person camera: ray casting over the grid (DDA) for walls, per-pixel floor
//! and ceiling casting, sign boards and pedestrians as planar sprites tested against a
//! per-column z-buffer, lighting with distance falloff, vignetting and sensor noise.
//!
//! The renderer also reports the ground truth of each frame ([`FrameTruth`]): for every
//! sign board, the box covering exactly the pixels where the board was drawn (same
//! rays, same projection), its depth and how much of it was visible.
//!
//! One renderer: the wall, floor, sprite and lighting passes share the camera, the
//! z-buffer and the frame buffer, and read best in order.
use crate::maze::{Dir, Lighting, Maze, Mount};
use crate::texture::{self, WallKind};
use frugal_data::sign::{SignStyle, render_sign};
use frugal_runtime::{BBox, ClassId};
use image::RgbaImage;

/// Camera intrinsics and mounting.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CameraSpec {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
    /// Camera height above the floor while flying, metres.
    pub altitude: f64,
}

impl Default for CameraSpec {
    /// 480×270, 70° horizontal field of view, 1.2 m above the floor.
    fn default() -> Self {
        Self {
            width: 480,
            height: 270,
            hfov_deg: 70.0,
            altitude: 1.2,
        }
    }
}

impl CameraSpec {
    /// Focal length in pixels (square pixels): `f = (W/2) / tan(hfov/2)`.
    pub fn focal_px(&self) -> f64 {
        f64::from(self.width) / 2.0 / (self.hfov_deg.to_radians() / 2.0).tan()
    }

    /// Distance along the optical axis of a vertical object of height `size` metres
    /// that appears `box_height` pixels tall: `d = f · H / h`.
    pub fn distance_from_height(&self, size: f64, box_height: f64) -> f64 {
        self.focal_px() * size / box_height.max(1e-6)
    }
}

/// Where the drone is: world metres and yaw (0 = east, +π/2 = south).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pose {
    /// East, metres.
    pub x: f64,
    /// South, metres.
    pub y: f64,
    /// Heading, radians.
    pub yaw: f64,
}

/// A sign board in world space.
#[derive(Clone, Debug)]
pub struct Board {
    /// Index into [`Maze::signs`].
    pub index: usize,
    /// Class id of the sign.
    pub class: ClassId,
    /// Left edge (seen from the front), world metres.
    pub a: (f64, f64),
    /// Right edge (seen from the front).
    pub b: (f64, f64),
    /// Unit normal of the front face.
    pub normal: (f64, f64),
    /// Centre height above the floor.
    pub z: f64,
    /// Edge length (square board).
    pub size: f64,
    /// Printed on both faces (flag mount).
    pub two_sided: bool,
    sprite: RgbaImage,
}

impl Board {
    /// The board's centre.
    pub fn center(&self) -> (f64, f64) {
        ((self.a.0 + self.b.0) / 2.0, (self.a.1 + self.b.1) / 2.0)
    }
}

/// Build the boards of a maze.
pub fn boards(maze: &Maze) -> Vec<Board> {
    let sprite_px = 160;
    maze.signs
        .iter()
        .enumerate()
        .map(|(index, s)| {
            let (sx, sy) = s.wall.vector();
            let (cx, cy) = crate::maze::cell_center(s.cell, maze.cell);
            let face = (cx + sx * maze.cell / 2.0, cy + sy * maze.cell / 2.0);
            let (center, normal) = match s.mount {
                // 1 cm off the wall, facing into the cell.
                Mount::Flat => ((face.0 - sx * 0.01, face.1 - sy * 0.01), (-sx, -sy)),
                // Sticking out of the wall 5 cm from it; normal along the wall.
                Mount::Flag => {
                    let off = 0.05 + maze.sign_size / 2.0;
                    ((face.0 - sx * off, face.1 - sy * off), (-sy, sx))
                }
            };
            // A viewer in front looks along -normal; its right is (n.y, -n.x).
            let right = (normal.1, -normal.0);
            let h = maze.sign_size / 2.0;
            Board {
                index,
                class: s.sign.id(),
                a: (center.0 - right.0 * h, center.1 - right.1 * h),
                b: (center.0 + right.0 * h, center.1 + right.1 * h),
                normal,
                z: s.height,
                size: maze.sign_size,
                two_sided: s.mount == Mount::Flag,
                sprite: render_sign(s.sign, sprite_px, &SignStyle::default()),
            }
        })
        .collect()
}

/// Ground truth of one sign board in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SignTruth {
    /// Index into [`Maze::signs`].
    pub sign: usize,
    /// Class id.
    pub class: ClassId,
    /// Box around exactly the drawn pixels of the board (x2/y2 exclusive).
    pub bbox: BBox,
    /// Depth along the optical axis at the box's centre column, metres.
    pub depth: f64,
    /// Visible columns ÷ columns the whole board would span on an unbounded screen.
    pub visible_fraction: f64,
}

/// Ground truth of one pedestrian in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PedestrianTruth {
    /// Index into [`Maze::zones`].
    pub zone: usize,
    /// Box around the billboard's visible columns (full body height).
    pub bbox: BBox,
    /// Depth along the optical axis, metres.
    pub depth: f64,
}

/// Everything visible in one frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameTruth {
    /// Sign boards with at least one visible column.
    pub signs: Vec<SignTruth>,
    /// Pedestrians with at least one visible column.
    pub pedestrians: Vec<PedestrianTruth>,
}

/// A pedestrian in the world at render time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Walker {
    /// Index into [`Maze::zones`].
    pub zone: usize,
    /// Position, world metres.
    pub pos: (f64, f64),
    /// Walking phase, radians (animates the legs).
    pub phase: f64,
}

struct Light {
    ambient: f32,
    falloff: f32,
    gain: f32,
    contrast: f32,
    tint: [f32; 3],
    vignette: f32,
    noise: f32,
    flicker: f32,
}

impl Light {
    fn of(l: Lighting) -> Light {
        match l {
            Lighting::Normal => Light {
                ambient: 0.45,
                falloff: 14.0,
                gain: 1.0,
                contrast: 1.0,
                tint: [1.0, 1.0, 1.0],
                vignette: 0.12,
                noise: 0.006,
                flicker: 0.01,
            },
            Lighting::Low => Light {
                ambient: 0.22,
                falloff: 6.0,
                gain: 0.4,
                contrast: 0.75,
                tint: [1.07, 0.96, 0.8],
                vignette: 0.35,
                noise: 0.02,
                flicker: 0.04,
            },
        }
    }

    fn at(&self, depth: f32) -> f32 {
        let d = depth / self.falloff;
        self.ambient + (1.0 - self.ambient) / (1.0 + d * d)
    }
}

/// A sprite in the per-frame draw list.
struct Sprite<'a> {
    a: (f64, f64),
    b: (f64, f64),
    z_bot: f64,
    z_top: f64,
    dist2: f64,
    kind: SpriteKind<'a>,
}

enum SpriteKind<'a> {
    Board(&'a Board),
    Walker(&'a Walker),
}

/// Per-sprite accumulation of what was drawn.
#[derive(Default, Clone, Copy)]
struct Coverage {
    visible: u32,
    x_min: u32,
    x_max: u32,
    y_min: f64,
    y_max: f64,
    depth_at_center: f64,
}

/// What one column's ray hit.
struct Column {
    d: (f64, f64),
    depth: f64,
    y_top: f64,
    y_bot: f64,
    face_hash: u64,
    kind: WallKind,
    light: f32,
    u: f32,
}

/// The renderer of one maze: owns the boards, a float frame buffer and a z-buffer.
pub struct Renderer {
    maze: Maze,
    camera: CameraSpec,
    seed: u64,
    boards: Vec<Board>,
    light: Light,
    buf: Vec<[f32; 3]>,
    zbuf: Vec<f64>,
    cols: Vec<Column>,
}

const NEAR: f64 = 0.05;

impl Renderer {
    /// A renderer for `maze` seen by `camera`; `seed` drives texture variation and noise.
    pub fn new(maze: &Maze, camera: CameraSpec, seed: u64) -> Renderer {
        let n = camera.width as usize * camera.height as usize;
        Renderer {
            boards: boards(maze),
            light: Light::of(maze.lighting),
            maze: maze.clone(),
            camera,
            seed,
            buf: vec![[0.0; 3]; n],
            zbuf: vec![f64::INFINITY; camera.width as usize],
            cols: Vec::with_capacity(camera.width as usize),
        }
    }

    /// The camera.
    pub fn camera(&self) -> &CameraSpec {
        &self.camera
    }

    /// The sign boards (world geometry).
    pub fn boards(&self) -> &[Board] {
        &self.boards
    }

    /// Render the view from `pose` with `walkers` in the scene into `rgb` (resized to
    /// `width * height * 3`, RGB8) and return what is visible. `frame` seeds the noise.
    pub fn render(
        &mut self,
        pose: Pose,
        walkers: &[Walker],
        frame: u64,
        rgb: &mut Vec<u8>,
    ) -> FrameTruth {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let f = self.camera.focal_px();
        let cy = h as f64 / 2.0;
        let alt = self.camera.altitude;
        let tan = (self.camera.hfov_deg.to_radians() / 2.0).tan();
        let fwd = (pose.yaw.cos(), pose.yaw.sin());
        let right = (-fwd.1, fwd.0);
        let cell = self.maze.cell;
        let wall_h = self.maze.wall_height;
        let ray = |x: usize| {
            let cam_x = ((x as f64 + 0.5) / w as f64 * 2.0 - 1.0) * tan;
            (fwd.0 + right.0 * cam_x, fwd.1 + right.1 * cam_x)
        };

        // Walls: one ray per column (DDA), kept for the row-major pass and the sprites.
        self.cols.clear();
        for x in 0..w {
            let d = ray(x);
            let hit = cast(&self.maze, pose.x / cell, pose.y / cell, d);
            let depth = hit.dist * cell;
            self.zbuf[x] = depth;
            let face_hash = texture::hash_n(&[hit.col, hit.row, hit.face as i64, self.seed as i64]);
            let shade = if hit.face == Dir::East || hit.face == Dir::West {
                0.86
            } else {
                1.0
            };
            self.cols.push(Column {
                d,
                depth,
                y_top: cy - f * (wall_h - alt) / depth,
                y_bot: cy + f * alt / depth,
                face_hash,
                kind: WallKind::of(face_hash),
                light: self.light.at(depth as f32) * shade,
                u: (hit.along * cell) as f32,
            });
        }

        // Walls, floor and ceiling, row by row (cache-friendly writes). Floor and
        // ceiling distances depend only on the row.
        for y in 0..h {
            let yc = y as f64 + 0.5;
            let ceil_dist = if yc < cy {
                (wall_h - alt) * f / (cy - yc)
            } else {
                0.0
            };
            let floor_dist = if yc > cy { alt * f / (yc - cy) } else { 0.0 };
            let ceil_light = self.light.at(ceil_dist as f32);
            let floor_light = self.light.at(floor_dist as f32);
            let row = &mut self.buf[y * w..(y + 1) * w];
            for (px, col) in row.iter_mut().zip(&self.cols) {
                *px = if yc < col.y_top {
                    let (wx, wy) = (pose.x + col.d.0 * ceil_dist, pose.y + col.d.1 * ceil_dist);
                    let (c, lamp) = texture::ceiling(wx as f32, wy as f32, cell as f32);
                    let l = if lamp { 1.0 } else { ceil_light };
                    c.map(|v| v * l)
                } else if yc < col.y_bot {
                    let z = alt + (cy - yc) * col.depth / f;
                    let c = texture::wall(col.kind, col.face_hash, col.u, z as f32);
                    c.map(|v| v * col.light)
                } else {
                    let (wx, wy) = (pose.x + col.d.0 * floor_dist, pose.y + col.d.1 * floor_dist);
                    let c = texture::floor(wx as f32, wy as f32, stripe(&self.maze, wx, wy));
                    c.map(|v| v * floor_light)
                };
            }
        }

        // Sprites, far to near.
        let (pw, ph) = texture::PEDESTRIAN_SIZE;
        let mut sprites: Vec<Sprite<'_>> = Vec::with_capacity(self.boards.len() + walkers.len());
        for b in &self.boards {
            let c = b.center();
            let in_front = (pose.x - c.0) * b.normal.0 + (pose.y - c.1) * b.normal.1 > 0.0;
            // Single-sided boards are invisible from behind; two-sided boards are
            // drawn unmirrored from both faces (two prints back to back).
            let (a, bb) = if in_front { (b.a, b.b) } else { (b.b, b.a) };
            if !in_front && !b.two_sided {
                continue;
            }
            sprites.push(Sprite {
                a,
                b: bb,
                z_bot: b.z - b.size / 2.0,
                z_top: b.z + b.size / 2.0,
                dist2: (c.0 - pose.x).powi(2) + (c.1 - pose.y).powi(2),
                kind: SpriteKind::Board(b),
            });
        }
        for wk in walkers {
            let (px, py) = wk.pos;
            sprites.push(Sprite {
                a: (px - right.0 * pw / 2.0, py - right.1 * pw / 2.0),
                b: (px + right.0 * pw / 2.0, py + right.1 * pw / 2.0),
                z_bot: 0.0,
                z_top: ph,
                dist2: (px - pose.x).powi(2) + (py - pose.y).powi(2),
                kind: SpriteKind::Walker(wk),
            });
        }
        sprites.sort_by(|p, q| q.dist2.total_cmp(&p.dist2));

        let mut truth = FrameTruth::default();
        for sp in &sprites {
            let cov = draw_sprite(
                &mut self.buf,
                &self.zbuf,
                &self.light,
                &self.camera,
                sp,
                pose,
                &ray,
            );
            let Some(cov) = cov else { continue };
            let bbox = BBox::new(
                cov.x_min as f32,
                cov.y_min.max(0.0) as f32,
                (cov.x_max + 1) as f32,
                cov.y_max.min(h as f64) as f32,
            );
            if !bbox.is_valid() {
                continue;
            }
            match sp.kind {
                SpriteKind::Board(b) => {
                    let span = projected_span(sp.a, sp.b, pose, f, w as f64);
                    truth.signs.push(SignTruth {
                        sign: b.index,
                        class: b.class,
                        bbox,
                        depth: cov.depth_at_center,
                        visible_fraction: (f64::from(cov.visible) / span.max(1.0)).min(1.0),
                    });
                }
                SpriteKind::Walker(wk) => truth.pedestrians.push(PedestrianTruth {
                    zone: wk.zone,
                    bbox,
                    depth: cov.depth_at_center,
                }),
            }
        }
        truth.signs.sort_by_key(|s| s.sign);

        self.finish(frame, rgb);
        truth
    }

    /// Photometric pass: gain, contrast, tint, vignette, flicker and sensor noise.
    fn finish(&self, frame: u64, rgb: &mut Vec<u8>) {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        rgb.resize(w * h * 3, 0);
        let l = &self.light;
        let fh = texture::hash_n(&[self.seed as i64, frame as i64, 17]);
        let gain = l.gain * (1.0 + (texture::unit(fh) * 2.0 - 1.0) * l.flicker);
        let (cx, cy) = (w as f32 / 2.0, h as f32 / 2.0);
        let r2max = cx * cx + cy * cy;
        let mut state = fh | 1;
        let k = [
            gain * l.tint[0] * l.contrast,
            gain * l.tint[1] * l.contrast,
            gain * l.tint[2] * l.contrast,
        ];
        let b = [
            gain * l.tint[0] * 0.5 * (1.0 - l.contrast),
            gain * l.tint[1] * 0.5 * (1.0 - l.contrast),
            gain * l.tint[2] * 0.5 * (1.0 - l.contrast),
        ];
        let noise = 2.45 * l.noise; // triangular noise, variance-matched
        let vig_k = l.vignette / r2max;
        let dx2: Vec<f32> = (0..w)
            .map(|x| {
                let dx = x as f32 + 0.5 - cx;
                dx * dx
            })
            .collect();
        for (y, (out_row, in_row)) in rgb
            .chunks_exact_mut(w * 3)
            .zip(self.buf.chunks_exact(w))
            .enumerate()
        {
            let dy = y as f32 + 0.5 - cy;
            let dy2 = dy * dy;
            for ((out, p), dx2) in out_row.chunks_exact_mut(3).zip(in_row).zip(&dx2) {
                // Gain, tint and contrast about mid-grey, then vignetting, in 0..255.
                let vig = (1.0 - vig_k * (dx2 + dy2)) * 255.0;
                // xorshift64 stream: three triangular noise samples per pixel.
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let bits = state;
                for (c, o) in out.iter_mut().enumerate() {
                    let a = ((bits >> (c * 16)) & 0xff) as f32;
                    let bb = ((bits >> (c * 16 + 8)) & 0xff) as f32;
                    let n = (a + bb - 255.0) * noise;
                    let v = (p[c] * k[c] + b[c]) * vig + n;
                    *o = (v.clamp(0.0, 255.0) + 0.5) as u8;
                }
            }
        }
    }
}

/// Draw one sprite column by column; returns what was visible.
fn draw_sprite(
    buf: &mut [[f32; 3]],
    zbuf: &[f64],
    light: &Light,
    camera: &CameraSpec,
    sp: &Sprite<'_>,
    pose: Pose,
    ray: &dyn Fn(usize) -> (f64, f64),
) -> Option<Coverage> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let f = camera.focal_px();
    let cy = h as f64 / 2.0;
    let alt = camera.altitude;
    let e = (sp.b.0 - sp.a.0, sp.b.1 - sp.a.1);
    let wv = (sp.a.0 - pose.x, sp.a.1 - pose.y);
    let mut cov: Option<Coverage> = None;
    let mut cols: Vec<(usize, f64)> = Vec::new();
    for x in 0..w {
        let d = ray(x);
        let det = -d.0 * e.1 + d.1 * e.0;
        if det.abs() < 1e-12 {
            continue;
        }
        let t = (-wv.0 * e.1 + e.0 * wv.1) / det;
        let s = (d.0 * wv.1 - d.1 * wv.0) / det;
        if !(0.0..1.0).contains(&s) || t < NEAR || t >= zbuf[x] {
            continue;
        }
        let y_top = cy - f * (sp.z_top - alt) / t;
        let y_bot = cy - f * (sp.z_bot - alt) / t;
        let light = light.at(t as f32);
        let mut drawn = false;
        let y0 = (y_top - 0.5).ceil().max(0.0) as usize;
        let y1 = ((y_bot - 0.5).ceil().max(0.0) as usize).min(h);
        for y in y0..y1 {
            let v = (y as f64 + 0.5 - y_top) / (y_bot - y_top);
            let (c, a) = match sp.kind {
                SpriteKind::Board(b) => sample(&b.sprite, s, v),
                SpriteKind::Walker(wk) => {
                    let (pw, ph) = texture::PEDESTRIAN_SIZE;
                    match texture::pedestrian(
                        ((s - 0.5) * pw) as f32,
                        ((1.0 - v) * ph) as f32,
                        wk.phase as f32,
                    ) {
                        Some(c) => (c, 1.0),
                        None => continue,
                    }
                }
            };
            if a <= 0.0 {
                continue;
            }
            drawn = true;
            let px = &mut buf[y * w + x];
            for k in 0..3 {
                px[k] = c[k] * light * a + px[k] * (1.0 - a);
            }
        }
        // Boards count every column they span (the box is the board's square, as
        // in the dataset); pedestrians only the columns where the body was drawn.
        if drawn || matches!(sp.kind, SpriteKind::Board(_)) {
            cols.push((x, t));
            let c = cov.get_or_insert(Coverage {
                visible: 0,
                x_min: x as u32,
                x_max: x as u32,
                y_min: f64::INFINITY,
                y_max: f64::NEG_INFINITY,
                depth_at_center: t,
            });
            c.visible += 1;
            c.x_max = x as u32;
            c.y_min = c.y_min.min(y_top);
            c.y_max = c.y_max.max(y_bot);
        }
    }
    if let Some(c) = cov.as_mut() {
        let mid = cols[cols.len() / 2];
        c.depth_at_center = mid.1;
    }
    cov
}

/// True where the floor point lies on the yellow band along a wall.
fn stripe(maze: &Maze, x: f64, y: f64) -> bool {
    let cell = maze.cell;
    let (c, r) = ((x / cell).floor(), (y / cell).floor());
    let (fx, fy) = (x - c * cell, y - r * cell);
    let band = |d: f64| (0.15..0.27).contains(&d);
    let (near_x, near_y) = (band(fx) || band(cell - fx), band(fy) || band(cell - fy));
    if !near_x && !near_y {
        return false;
    }
    let (c, r) = (c as i64, r as i64);
    (band(fx) && maze.is_wall(c - 1, r))
        || (band(cell - fx) && maze.is_wall(c + 1, r))
        || (band(fy) && maze.is_wall(c, r - 1))
        || (band(cell - fy) && maze.is_wall(c, r + 1))
}

/// Bilinear RGBA sample of a sprite at `(u, v)` in `[0, 1)²`; colour and alpha in 0..1.
fn sample(img: &RgbaImage, u: f64, v: f64) -> ([f32; 3], f32) {
    let (iw, ih) = (img.width() as f64, img.height() as f64);
    let fx = (u * iw - 0.5).clamp(0.0, iw - 1.0);
    let fy = (v * ih - 0.5).clamp(0.0, ih - 1.0);
    let (x0, y0) = (fx.floor() as u32, fy.floor() as u32);
    let (x1, y1) = (
        (x0 + 1).min(img.width() - 1),
        (y0 + 1).min(img.height() - 1),
    );
    let (tx, ty) = ((fx - f64::from(x0)) as f32, (fy - f64::from(y0)) as f32);
    let mut acc = [0.0f32; 4];
    for (x, y, wgt) in [
        (x0, y0, (1.0 - tx) * (1.0 - ty)),
        (x1, y0, tx * (1.0 - ty)),
        (x0, y1, (1.0 - tx) * ty),
        (x1, y1, tx * ty),
    ] {
        let p = img.get_pixel(x, y).0;
        let a = f32::from(p[3]) / 255.0 * wgt;
        for k in 0..3 {
            acc[k] += f32::from(p[k]) / 255.0 * a;
        }
        acc[3] += a;
    }
    if acc[3] <= 0.0 {
        return ([0.0; 3], 0.0);
    }
    ([acc[0] / acc[3], acc[1] / acc[3], acc[2] / acc[3]], acc[3])
}

/// How many columns the segment `a..b` would span on an unbounded screen (after
/// clipping at the near plane).
fn projected_span(a: (f64, f64), b: (f64, f64), pose: Pose, f: f64, w: f64) -> f64 {
    let fwd = (pose.yaw.cos(), pose.yaw.sin());
    let right = (-fwd.1, fwd.0);
    let cam = |p: (f64, f64)| {
        let (dx, dy) = (p.0 - pose.x, p.1 - pose.y);
        (dx * fwd.0 + dy * fwd.1, dx * right.0 + dy * right.1)
    };
    let (mut pa, mut pb) = (cam(a), cam(b));
    if pa.0 < NEAR && pb.0 < NEAR {
        return 0.0;
    }
    let clip = |p: (f64, f64), q: (f64, f64)| {
        let t = (NEAR - p.0) / (q.0 - p.0);
        (NEAR, p.1 + (q.1 - p.1) * t)
    };
    if pa.0 < NEAR {
        pa = clip(pa, pb);
    } else if pb.0 < NEAR {
        pb = clip(pb, pa);
    }
    let xa = w / 2.0 + f * pa.1 / pa.0;
    let xb = w / 2.0 + f * pb.1 / pb.0;
    (xa - xb).abs()
}

/// A wall hit of one ray.
struct Hit {
    /// Perpendicular distance in cells.
    dist: f64,
    col: i64,
    row: i64,
    /// Which face of the wall cell was hit (the side facing the viewer).
    face: Dir,
    /// Position along the face, 0..1.
    along: f64,
}

/// DDA over the grid from `(px, py)` (cell units) along `d` (not normalised; the
/// returned distance is the perpendicular depth when `d`'s forward component is 1).
fn cast(maze: &Maze, px: f64, py: f64, d: (f64, f64)) -> Hit {
    let (mut col, mut row) = (px.floor() as i64, py.floor() as i64);
    let ddx = if d.0 == 0.0 {
        f64::INFINITY
    } else {
        (1.0 / d.0).abs()
    };
    let ddy = if d.1 == 0.0 {
        f64::INFINITY
    } else {
        (1.0 / d.1).abs()
    };
    let (step_x, mut side_x) = if d.0 < 0.0 {
        (-1, (px - col as f64) * ddx)
    } else {
        (1, (col as f64 + 1.0 - px) * ddx)
    };
    let (step_y, mut side_y) = if d.1 < 0.0 {
        (-1, (py - row as f64) * ddy)
    } else {
        (1, (row as f64 + 1.0 - py) * ddy)
    };
    // Leaving the map hits the implicit outer wall, so the loop ends within
    // width + height steps.
    let limit = maze.width + maze.height + 4;
    let mut x_side = true;
    if maze.is_wall(col, row) {
        return Hit {
            dist: NEAR,
            col,
            row,
            face: Dir::North,
            along: 0.0,
        };
    }
    for _ in 0..limit {
        if side_x < side_y {
            side_x += ddx;
            col += step_x;
            x_side = true;
        } else {
            side_y += ddy;
            row += step_y;
            x_side = false;
        }
        if maze.is_wall(col, row) {
            break;
        }
    }
    let dist = if x_side { side_x - ddx } else { side_y - ddy }.max(1e-4);
    let (face, along) = if x_side {
        let yy = py + dist * d.1;
        (
            if step_x > 0 { Dir::West } else { Dir::East },
            yy - yy.floor(),
        )
    } else {
        let xx = px + dist * d.0;
        (
            if step_y > 0 { Dir::North } else { Dir::South },
            xx - xx.floor(),
        )
    };
    Hit {
        dist,
        col,
        row,
        face,
        along,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn corridor() -> Maze {
        Maze::parse(
            "cell 3\nstart 1 1 east\ngoal 4 1\nsign stop 4 1 e 1.2\nmap\n######\n#....#\n######\nend\n",
            Path::new("c.maze"),
        )
        .unwrap()
    }

    #[test]
    fn dda_depth_matches_the_geometry() {
        let m = corridor();
        // From x = 4.5 m looking east, the east wall face is at x = 15 m.
        let h = cast(&m, 4.5 / 3.0, 4.5 / 3.0, (1.0, 0.0));
        assert!((h.dist * 3.0 - 10.5).abs() < 1e-9);
        assert_eq!((h.col, h.row, h.face), (5, 1, Dir::West));
        let h = cast(&m, 4.5 / 3.0, 4.5 / 3.0, (0.0, -1.0));
        assert!((h.dist * 3.0 - 1.5).abs() < 1e-9);
    }

    #[test]
    fn rendering_is_deterministic_per_seed() {
        let m = corridor();
        let cam = CameraSpec {
            width: 96,
            height: 54,
            ..CameraSpec::default()
        };
        let pose = Pose {
            x: 4.5,
            y: 4.5,
            yaw: 0.0,
        };
        let (mut a, mut b, mut c) = (Vec::new(), Vec::new(), Vec::new());
        let ta = Renderer::new(&m, cam, 1).render(pose, &[], 0, &mut a);
        let tb = Renderer::new(&m, cam, 1).render(pose, &[], 0, &mut b);
        Renderer::new(&m, cam, 2).render(pose, &[], 0, &mut c);
        assert_eq!(a, b);
        assert_eq!(ta, tb);
        assert_ne!(a, c);
        assert_eq!(ta.signs.len(), 1);
    }
}
