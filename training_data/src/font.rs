//! A small stroke font (upper-case letters, digits, a few symbols) drawn with the
//! anti-aliased rasterizer: used for the letters on signs ("STOP", "30", "5t") and for
//! the labels that `frugal data show` writes onto frames. Glyphs are polylines on a
//! 4 × 6 grid, y down.
use crate::raster::{P, Shape};

/// Polylines of one glyph, `;`-separated, points `x,y` separated by spaces.
fn glyph(c: char) -> &'static str {
    match c.to_ascii_uppercase() {
        'A' => "0,6 0,2 2,0 4,2 4,6; 0,3.5 4,3.5",
        'B' => "0,0 0,6 3,6 4,5 4,4 3,3 0,3; 0,0 3,0 4,1 4,2 3,3",
        'C' => "4,0 1,0 0,1 0,5 1,6 4,6",
        'D' => "0,0 0,6 2.5,6 4,4.5 4,1.5 2.5,0 0,0",
        'E' => "4,0 0,0 0,6 4,6; 0,3 3,3",
        'F' => "4,0 0,0 0,6; 0,3 3,3",
        'G' => "4,1 3,0 1,0 0,1 0,5 1,6 3,6 4,5 4,3 2,3",
        'H' => "0,0 0,6; 4,0 4,6; 0,3 4,3",
        'I' => "1,0 3,0; 2,0 2,6; 1,6 3,6",
        'J' => "4,0 4,5 3,6 1,6 0,5",
        'K' => "0,0 0,6; 4,0 0,3.5; 1.3,2.7 4,6",
        'L' => "0,0 0,6 4,6",
        'M' => "0,6 0,0 2,3 4,0 4,6",
        'N' => "0,6 0,0 4,6 4,0",
        'O' => "1,0 3,0 4,1 4,5 3,6 1,6 0,5 0,1 1,0",
        'P' => "0,6 0,0 3,0 4,1 4,2 3,3 0,3",
        'Q' => "1,0 3,0 4,1 4,5 3,6 1,6 0,5 0,1 1,0; 2.5,4.5 4,6",
        'R' => "0,6 0,0 3,0 4,1 4,2 3,3 0,3; 2,3 4,6",
        'S' => "4,1 3,0 1,0 0,1 0,2 1,3 3,3 4,4 4,5 3,6 1,6 0,5",
        'T' => "0,0 4,0; 2,0 2,6",
        'U' => "0,0 0,5 1,6 3,6 4,5 4,0",
        'V' => "0,0 2,6 4,0",
        'W' => "0,0 1,6 2,3 3,6 4,0",
        'X' => "0,0 4,6; 4,0 0,6",
        'Y' => "0,0 2,3 4,0; 2,3 2,6",
        'Z' => "0,0 4,0 0,6 4,6",
        '0' => "1,0 3,0 4,1 4,5 3,6 1,6 0,5 0,1 1,0; 3.5,1 0.5,5",
        '1' => "1,1 2,0 2,6; 1,6 3,6",
        '2' => "0,1 1,0 3,0 4,1 4,2 0,6 4,6",
        '3' => "0,1 1,0 3,0 4,1 4,2 3,3 4,4 4,5 3,6 1,6 0,5; 1.5,3 3,3",
        '4' => "3,6 3,0 0,4 4,4",
        '5' => "4,0 0,0 0,3 3,3 4,4 4,5 3,6 0,6",
        '6' => "3,0 1,0 0,1 0,5 1,6 3,6 4,5 4,4 3,3 0,3",
        '7' => "0,0 4,0 1.5,6",
        '8' => "1,0 3,0 4,1 4,2 3,3 1,3 0,2 0,1 1,0; 1,3 0,4 0,5 1,6 3,6 4,5 4,4 3,3",
        '9' => "4,3 1,3 0,2 0,1 1,0 3,0 4,1 4,5 3,6 1,6",
        '_' => "0,6 4,6",
        '-' => "0.5,3 3.5,3",
        '.' => "2,5.7 2,6",
        ':' => "2,1.8 2,2.1; 2,4.9 2,5.2",
        '/' => "4,0 0,6",
        '%' => "4,0 0,6; 0.6,0.6 0.8,0.8; 3.2,5.2 3.4,5.4",
        '=' => "0.5,2 3.5,2; 0.5,4 3.5,4",
        '!' => "2,0 2,4; 2,5.7 2,6",
        '(' => "3,0 2,1 2,5 3,6",
        ')' => "1,0 2,1 2,5 1,6",
        '#' => "1,0 1,6; 3,0 3,6; 0,2 4,2; 0,4 4,4",
        '+' => "2,1.5 2,4.5; 0.5,3 3.5,3",
        _ => "",
    }
}

/// The lower-case `t` used on the C21 sign (other lower-case letters draw as capitals).
const LOWER_T: &str = "1.5,0.5 1.5,5 2.5,6 3.5,6; 0.3,2 3.3,2";

/// Width of a string in grid units (4 per glyph, 1 between glyphs).
fn units(text: &str) -> f32 {
    let n = text.chars().count() as f32;
    if n == 0.0 { 0.0 } else { n * 5.0 - 1.0 }
}

/// The width in pixels of `text` drawn with glyph height `height`.
pub fn text_width(text: &str, height: f32) -> f32 {
    units(text) * height / 6.0
}

/// The strokes of `text` with its top-left corner at `origin` and glyph height
/// `height`, stroke half-width `weight * height`.
pub fn text_shape(text: &str, origin: P, height: f32, weight: f32) -> Shape {
    let s = height / 6.0;
    let hw = weight * height;
    let mut segs = Vec::new();
    for (i, c) in text.chars().enumerate() {
        let g = if c == 't' { LOWER_T } else { glyph(c) };
        let x0 = origin.0 + i as f32 * 5.0 * s;
        for line in g.split(';') {
            let pts: Vec<P> = line
                .split_whitespace()
                .filter_map(|p| {
                    let (x, y) = p.split_once(',')?;
                    Some((x.parse::<f32>().ok()?, y.parse::<f32>().ok()?))
                })
                .map(|(x, y)| (x0 + x * s, origin.1 + y * s))
                .collect();
            for w in pts.windows(2) {
                segs.push(Shape::Seg(w[0], w[1], hw));
            }
        }
    }
    Shape::Union(segs)
}

/// The strokes of `text` centred on `center`.
pub fn text_centered(text: &str, center: P, height: f32, weight: f32) -> Shape {
    let w = text_width(text, height);
    text_shape(
        text,
        (center.0 - w * 0.5, center.1 - height * 0.5),
        height,
        weight,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_label_character_has_a_glyph() {
        for c in "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-.:/%=!()#+".chars() {
            assert!(!glyph(c).is_empty(), "{c}");
            if let Shape::Union(v) = text_shape(&c.to_string(), (0.0, 0.0), 12.0, 0.08) {
                assert!(!v.is_empty(), "{c}");
            }
        }
        assert_eq!(text_width("AB", 6.0), 9.0);
        let (lo, hi) = text_centered("STOP", (50.0, 50.0), 12.0, 0.08).bounds();
        assert!((lo.0 + hi.0 - 100.0).abs() < 1.0 && (lo.1 + hi.1 - 100.0).abs() < 1.0);
    }
}
