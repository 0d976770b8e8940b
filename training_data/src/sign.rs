//! Procedural sign rendering. Each sign is a stack of anti-aliased layers (rim,
//! field, ring, pictogram) defined in unit coordinates `[-1, 1]²`; the first layer is
//! the sign's outline and gives its alpha. The same code draws the sprites of
//! [`render_sign`] and the signs composited into generated frames, and the maze
//! simulator can reuse [`render_sign`] for sign boards.
use crate::Sign;
use crate::font::text_centered;
use crate::raster::{Canvas, Shape};
use image::{Rgba, RgbaImage};

const RIM: [f32; 3] = [0.94, 0.94, 0.92];
const WHITE: [f32; 3] = [0.96, 0.96, 0.95];
const RED: [f32; 3] = [0.80, 0.07, 0.10];
const BLUE: [f32; 3] = [0.04, 0.30, 0.68];
const BLACK: [f32; 3] = [0.07, 0.07, 0.08];

/// How a sign looks apart from its class: wear and brightness.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SignStyle {
    /// 0 = new, 1 = completely washed out towards grey.
    pub fade: f32,
    /// Multiplies every colour (1 = as printed).
    pub brightness: f32,
}

impl Default for SignStyle {
    fn default() -> Self {
        Self {
            fade: 0.0,
            brightness: 1.0,
        }
    }
}

impl SignStyle {
    fn apply(&self, c: [f32; 3]) -> [f32; 3] {
        let grey = (c[0] + c[1] + c[2]) / 3.0;
        let f = self.fade.clamp(0.0, 1.0) * 0.6;
        c.map(|v| ((v + (grey * 0.9 + 0.08 - v) * f) * self.brightness).clamp(0.0, 1.0))
    }
}

fn octagon(apothem: f32) -> Shape {
    let r = apothem / (std::f32::consts::PI / 8.0).cos();
    Shape::Poly(
        (0..8)
            .map(|k| {
                let a = std::f32::consts::PI / 8.0 + k as f32 * std::f32::consts::PI / 4.0;
                (r * a.cos(), r * a.sin())
            })
            .collect(),
    )
}

/// An upward triangle scaled by `s` about its incentre.
fn triangle(s: f32) -> Shape {
    let c = 0.223;
    let v = [(0.0, -0.93), (1.0, 0.8), (-1.0, 0.8)];
    Shape::Poly(v.iter().map(|&(x, y)| (x * s, c + (y - c) * s)).collect())
}

/// Arrow pointing left (`dir = -1`) or right (`dir = 1`).
fn arrow(dir: f32) -> Shape {
    Shape::Union(vec![
        Shape::Seg((-0.55 * dir, 0.0), (0.05 * dir, 0.0), 0.13),
        Shape::Poly(vec![
            (0.62 * dir, 0.0),
            (0.1 * dir, -0.42),
            (0.1 * dir, 0.42),
        ]),
    ])
}

fn disc_with_ring(field: [f32; 3]) -> Vec<(Shape, [f32; 3])> {
    vec![
        (Shape::Disc((0.0, 0.0), 1.0), RIM),
        (Shape::Disc((0.0, 0.0), 0.93), field),
        (Shape::Ring((0.0, 0.0), 0.93, 0.72), RED),
    ]
}

/// The layers of a sign in unit coordinates; the first is the outline.
pub fn layers(sign: Sign) -> Vec<(Shape, [f32; 3])> {
    let slash = || Shape::Seg((-0.56, -0.56), (0.56, 0.56), 0.1);
    match sign {
        Sign::TurnLeft | Sign::TurnRight => {
            let dir = if sign == Sign::TurnLeft { -1.0 } else { 1.0 };
            vec![
                (Shape::Disc((0.0, 0.0), 1.0), RIM),
                (Shape::Disc((0.0, 0.0), 0.92), BLUE),
                (arrow(dir), WHITE),
            ]
        }
        Sign::Stop => vec![
            (octagon(1.0), RIM),
            (octagon(0.92), RED),
            (text_centered("STOP", (0.0, 0.0), 0.46, 0.085), WHITE),
        ],
        Sign::Wait => vec![
            (Shape::Rect((-1.0, -1.0), (1.0, 1.0), 0.16), RIM),
            (Shape::Rect((-0.92, -0.92), (0.92, 0.92), 0.1), BLUE),
            (
                Shape::Poly(vec![(0.0, -0.78), (0.76, 0.62), (-0.76, 0.62)]),
                WHITE,
            ),
            (
                Shape::Union(vec![
                    Shape::Disc((0.04, -0.34), 0.1),
                    Shape::Seg((0.02, -0.2), (-0.04, 0.12), 0.07),
                    Shape::Seg((-0.04, 0.12), (-0.24, 0.46), 0.055),
                    Shape::Seg((-0.04, 0.12), (0.18, 0.46), 0.055),
                    Shape::Seg((0.0, -0.14), (-0.22, 0.06), 0.045),
                    Shape::Seg((0.0, -0.14), (0.2, 0.04), 0.045),
                ]),
                BLACK,
            ),
        ],
        Sign::A14 => vec![
            (triangle(1.0), RIM),
            (triangle(0.92), RED),
            (triangle(0.64), WHITE),
            (
                Shape::Union(vec![
                    Shape::Seg((0.0, -0.2), (0.0, 0.3), 0.075),
                    Shape::Disc((0.0, 0.5), 0.085),
                ]),
                BLACK,
            ),
        ],
        Sign::E1 => {
            let mut l = disc_with_ring(BLUE);
            l.push((slash(), RED));
            l
        }
        Sign::C1 => vec![
            (Shape::Disc((0.0, 0.0), 1.0), RIM),
            (Shape::Disc((0.0, 0.0), 0.93), RED),
            (Shape::Rect((-0.66, -0.17), (0.66, 0.17), 0.0), WHITE),
        ],
        Sign::C43 => {
            let mut l = disc_with_ring(WHITE);
            l.push((text_centered("30", (0.0, 0.0), 0.72, 0.1), BLACK));
            l
        }
        Sign::C31R => {
            let mut l = disc_with_ring(WHITE);
            l.push((
                Shape::Union(vec![
                    Shape::Seg((-0.22, 0.5), (-0.22, -0.02), 0.1),
                    Shape::Seg((-0.22, -0.02), (0.14, -0.02), 0.1),
                    Shape::Poly(vec![(0.5, -0.02), (0.12, -0.34), (0.12, 0.3)]),
                ]),
                BLACK,
            ));
            l.push((slash(), RED));
            l
        }
        Sign::C21 => {
            let mut l = disc_with_ring(WHITE);
            l.push((text_centered("5t", (0.0, 0.0), 0.66, 0.1), BLACK));
            l
        }
    }
}

/// Paint `sign` into `canvas`, centred at `center` with half-width `hw` and
/// half-height `hh` in pixels. Returns the outline shape in canvas coordinates (its
/// coverage is the sign's alpha).
pub fn paint_sign(
    canvas: &mut Canvas,
    sign: Sign,
    center: (f32, f32),
    hw: f32,
    hh: f32,
    style: &SignStyle,
) -> Shape {
    let mut outline = None;
    for (shape, color) in layers(sign) {
        let mapped = shape.mapped(hw, hh, center.0, center.1);
        canvas.fill(&mapped, style.apply(color), 1.0);
        outline.get_or_insert(mapped);
    }
    outline.unwrap_or(Shape::Union(Vec::new()))
}

/// Render `sign` as a `size_px × size_px` RGBA sprite: anti-aliased edges, alpha 0
/// outside the sign, straight (not premultiplied) alpha.
///
/// ```
/// use frugal_data::{Sign, sign::{SignStyle, render_sign}};
/// let img = render_sign(Sign::Stop, 64, &SignStyle::default());
/// assert_eq!(img.dimensions(), (64, 64));
/// assert_eq!(img.get_pixel(0, 0)[3], 0); // corner of an octagon is transparent
/// assert_eq!(img.get_pixel(32, 32)[3], 255);
/// ```
pub fn render_sign(sign: Sign, size_px: u32, style: &SignStyle) -> RgbaImage {
    let n = size_px.max(1) as usize;
    let half = n as f32 * 0.5;
    let mut canvas = Canvas::new(n, n, [0.0; 3]);
    let outline = paint_sign(&mut canvas, sign, (half, half), half, half, style);
    let alpha = crate::raster::coverage(&outline, n, n);
    // Colours at partially covered edge pixels were blended with black: un-blend them.
    RgbaImage::from_fn(size_px.max(1), size_px.max(1), |x, y| {
        let i = y as usize * n + x as usize;
        let a = alpha[i];
        let c = canvas.px[i];
        let un = |v: f32| {
            if a > 0.0 {
                (v / a).clamp(0.0, 1.0)
            } else {
                0.0
            }
        };
        Rgba([to_u8(un(c[0])), to_u8(un(c[1])), to_u8(un(c[2])), to_u8(a)])
    })
}

/// `0..1` to `0..=255`, rounded.
pub fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_sign_renders_opaque_inside_and_transparent_outside() {
        for sign in Sign::ALL {
            let img = render_sign(sign, 48, &SignStyle::default());
            assert_eq!(img.get_pixel(24, 26)[3], 255, "{sign:?} centre");
            let opaque = img.pixels().filter(|p| p[3] == 255).count();
            let clear = img.pixels().filter(|p| p[3] == 0).count();
            let partial = img.pixels().filter(|p| p[3] > 0 && p[3] < 255).count();
            assert!(opaque > 48 * 48 / 3, "{sign:?} {opaque}");
            assert!(partial > 20, "{sign:?} edges are anti-aliased ({partial})");
            if sign != Sign::Wait {
                assert!(clear > 100, "{sign:?} corners are transparent ({clear})");
            }
        }
    }

    #[test]
    fn signs_are_pairwise_different() {
        let imgs: Vec<_> = Sign::ALL
            .iter()
            .map(|&s| render_sign(s, 40, &SignStyle::default()))
            .collect();
        for i in 0..imgs.len() {
            for j in i + 1..imgs.len() {
                let diff: u64 = imgs[i]
                    .as_raw()
                    .iter()
                    .zip(imgs[j].as_raw())
                    .map(|(&a, &b)| u64::from(a.abs_diff(b)))
                    .sum();
                assert!(
                    diff > 40 * 40 * 20,
                    "{:?} vs {:?}: {diff}",
                    Sign::ALL[i],
                    Sign::ALL[j]
                );
            }
        }
    }

    #[test]
    fn turn_left_is_the_mirror_of_turn_right_and_points_left() {
        let n = 64;
        let left = render_sign(Sign::TurnLeft, n, &SignStyle::default());
        let right = render_sign(Sign::TurnRight, n, &SignStyle::default());
        assert_ne!(left, right);
        let mirrored = image::imageops::flip_horizontal(&right);
        let max_diff = left
            .as_raw()
            .iter()
            .zip(mirrored.as_raw())
            .map(|(&a, &b)| a.abs_diff(b))
            .max()
            .unwrap_or(0);
        assert!(max_diff <= 2, "pictogram is mirrored exactly ({max_diff})");
        // The arrow head (the wide white part) lies on the left for turn_left.
        let white_cols = |img: &RgbaImage, x0: u32, x1: u32| {
            (x0..x1)
                .flat_map(|x| (0..n).map(move |y| (x, y)))
                .filter(|&(x, y)| img.get_pixel(x, y)[2] > 200 && img.get_pixel(x, y)[0] > 200)
                .count()
        };
        assert!(white_cols(&left, 12, 28) > white_cols(&left, 36, 52));
        assert!(white_cols(&right, 36, 52) > white_cols(&right, 12, 28));
    }
}
