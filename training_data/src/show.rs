//! Pictures for people: frames with their boxes and class labels drawn on, and contact
//! sheets (a grid of annotated thumbnails across every scenario level).
use crate::dataset::write_atomic;
use crate::font::{text_shape, text_width};
use crate::raster::{Shape, for_each_coverage};
use crate::{ClassId, ClassInfo, Clutter, DataError, Dataset, FrameRecord, Light, Object, Split};
use image::RgbImage;
use std::path::Path;

/// A distinct colour per class (a fixed palette, cycled).
pub fn class_color(class: ClassId) -> [u8; 3] {
    const PALETTE: [[u8; 3]; 10] = [
        [0, 255, 90],
        [255, 200, 0],
        [255, 60, 60],
        [60, 200, 255],
        [255, 120, 255],
        [160, 255, 60],
        [255, 140, 40],
        [120, 140, 255],
        [0, 230, 220],
        [255, 255, 255],
    ];
    PALETTE[usize::from(class) % PALETTE.len()]
}

fn blend(img: &mut RgbImage, shape: &Shape, color: [u8; 3], alpha: f32) {
    let (w, h) = (img.width() as usize, img.height() as usize);
    for_each_coverage(shape, w, h, |x, y, c| {
        let p = img.get_pixel_mut(x as u32, y as u32);
        let a = c * alpha;
        for k in 0..3 {
            p[k] = (f32::from(p[k]) + (f32::from(color[k]) - f32::from(p[k])) * a).round() as u8;
        }
    });
}

/// Draw `text` (upper-cased) with its top-left corner at `(x, y)`, glyph height
/// `height` pixels, on a dark band so it reads on any background.
pub fn draw_label(img: &mut RgbImage, text: &str, x: f32, y: f32, height: f32, color: [u8; 3]) {
    let text = text.to_uppercase();
    let pad = (height * 0.25).max(1.0);
    let w = text_width(&text, height);
    let (iw, ih) = (img.width() as f32, img.height() as f32);
    let x = x.min(iw - w - 2.0 * pad).max(0.0);
    let y = y.min(ih - height - 2.0 * pad).max(0.0);
    let band = Shape::Rect((x, y), (x + w + 2.0 * pad, y + height + 2.0 * pad), 0.0);
    blend(img, &band, [0, 0, 0], 0.7);
    blend(
        img,
        &text_shape(&text, (x + pad, y + pad), height, 0.07),
        color,
        1.0,
    );
}

/// Draw a 1-pixel box outline (inside the box's exclusive edges).
pub fn draw_box(img: &mut RgbImage, b: crate::BBox, color: [u8; 3]) {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let x1 = b.x1.round() as i64;
    let y1 = b.y1.round() as i64;
    let x2 = b.x2.round() as i64 - 1;
    let y2 = b.y2.round() as i64 - 1;
    let mut put = |x: i64, y: i64| {
        if (0..w).contains(&x) && (0..h).contains(&y) {
            img.put_pixel(x as u32, y as u32, image::Rgb(color));
        }
    };
    for x in x1..=x2 {
        put(x, y1);
        put(x, y2);
    }
    for y in y1..=y2 {
        put(x1, y);
        put(x2, y);
    }
}

/// Draw boxes and class names of `objects` onto `img`; boxes are scaled by `scale`
/// (for thumbnails).
pub fn draw_objects(
    img: &mut RgbImage,
    objects: &[Object],
    classes: &[ClassInfo],
    scale: f32,
    label_px: f32,
) {
    for o in objects {
        let color = class_color(o.class);
        let b = o.bbox;
        let b = crate::BBox::new(b.x1 * scale, b.y1 * scale, b.x2 * scale, b.y2 * scale);
        draw_box(img, b, color);
        let name = classes
            .get(usize::from(o.class))
            .map_or_else(|| o.class.to_string(), |c| c.name.clone());
        let ly = if b.y1 >= label_px * 1.6 {
            b.y1 - label_px * 1.5
        } else {
            b.y2 + 1.0
        };
        draw_label(img, &name, b.x1, ly, label_px, color);
    }
}

/// A frame of `ds` with its boxes and labels drawn on.
pub fn annotated_frame(ds: &Dataset, frame: &FrameRecord) -> Result<RgbImage, DataError> {
    let mut img = ds.load_rgb(frame)?;
    draw_objects(&mut img, &frame.objects, &ds.classes, 1.0, 8.0);
    Ok(img)
}

/// Contact-sheet layout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SheetOptions {
    /// Tiles per row.
    pub cols: u32,
    /// Thumbnail width.
    pub thumb_w: u32,
    /// Thumbnail height.
    pub thumb_h: u32,
    /// Frames per (clutter, light) scenario level.
    pub per_level: u32,
}

impl Default for SheetOptions {
    fn default() -> Self {
        Self {
            cols: 4,
            thumb_w: 240,
            thumb_h: 135,
            per_level: 2,
        }
    }
}

/// The frames a contact sheet shows: for each scenario level (clutter low → high,
/// light normal → low), `per_level` frames from different videos (taken from the
/// splits in turn: test, train, val), each the frame of its video with the most
/// objects and, among those, the largest boxes.
pub fn sheet_frames(ds: &Dataset, per_level: u32) -> Vec<&FrameRecord> {
    let mut out = Vec::new();
    for clutter in Clutter::ALL {
        for light in Light::ALL {
            let mut by_split: Vec<Vec<u32>> = [Split::Test, Split::Train, Split::Val]
                .iter()
                .map(|&s| {
                    ds.videos
                        .iter()
                        .filter(|v| v.clutter == clutter && v.light == light && v.split == s)
                        .map(|v| v.id)
                        .rev()
                        .collect()
                })
                .collect();
            let mut videos = Vec::new();
            while videos.len() < per_level as usize && by_split.iter().any(|v| !v.is_empty()) {
                for list in &mut by_split {
                    if videos.len() < per_level as usize
                        && let Some(v) = list.pop()
                    {
                        videos.push(v);
                    }
                }
            }
            for v in videos {
                let score = |f: &&FrameRecord| {
                    let area: f32 = f.objects.iter().map(|o| o.bbox.area()).sum();
                    (f.objects.len(), area as u64, std::cmp::Reverse(f.index))
                };
                out.extend(ds.frames.iter().filter(|f| f.video == v).max_by_key(score));
            }
        }
    }
    out
}

/// A grid of annotated thumbnails, captioned with scenario, split, video and frame.
pub fn contact_sheet(ds: &Dataset, opts: &SheetOptions) -> Result<RgbImage, DataError> {
    let frames = sheet_frames(ds, opts.per_level);
    if frames.is_empty() {
        return Err(DataError::Empty {
            path: ds.root.clone(),
            reason: "no frames to show".into(),
        });
    }
    let cols = opts.cols.max(1);
    let rows = (frames.len() as u32).div_ceil(cols);
    let gap = 2;
    let mut sheet = RgbImage::from_pixel(
        cols * (opts.thumb_w + gap) + gap,
        rows * (opts.thumb_h + gap) + gap,
        image::Rgb([30, 30, 30]),
    );
    for (i, f) in frames.iter().enumerate() {
        let img = ds.load_rgb(f)?;
        let mut thumb = image::imageops::resize(
            &img,
            opts.thumb_w,
            opts.thumb_h,
            image::imageops::FilterType::Triangle,
        );
        let scale = opts.thumb_w as f32 / f.width as f32;
        draw_objects(&mut thumb, &f.objects, &ds.classes, scale, 6.0);
        let caption = ds.video(f.video).map_or_else(
            || format!("V{} F{}", f.video, f.index),
            |v| {
                format!(
                    "{}/{} {} V{} F{}",
                    v.clutter.name(),
                    v.light.name(),
                    f.split,
                    f.video,
                    f.index
                )
            },
        );
        draw_label(&mut thumb, &caption, 0.0, 0.0, 7.0, [255, 255, 255]);
        let (c, r) = (i as u32 % cols, i as u32 / cols);
        image::imageops::replace(
            &mut sheet,
            &thumb,
            i64::from(gap + c * (opts.thumb_w + gap)),
            i64::from(gap + r * (opts.thumb_h + gap)),
        );
    }
    Ok(sheet)
}

/// Save an RGB image as PNG, through a temporary file and a rename.
pub fn save_png(img: &RgbImage, path: &Path) -> Result<(), DataError> {
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut bytes,
        image::codecs::png::CompressionType::Best,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(
        img.as_raw(),
        img.width(),
        img.height(),
        image::ExtendedColorType::Rgb8,
    )
    .map_err(|e| DataError::image(path, e))?;
    write_atomic(path, &bytes)
}

use image::ImageEncoder;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BBox;

    #[test]
    fn boxes_and_labels_change_the_pixels_they_should() {
        let mut img = RgbImage::from_pixel(60, 40, image::Rgb([100, 100, 100]));
        let o = Object {
            class: 2,
            bbox: BBox::new(20.0, 20.0, 40.0, 35.0),
        };
        draw_objects(&mut img, &[o], &crate::classes(), 1.0, 6.0);
        assert_eq!(img.get_pixel(20, 25).0, class_color(2));
        assert_eq!(img.get_pixel(39, 34).0, class_color(2));
        assert_eq!(img.get_pixel(30, 27).0, [100, 100, 100], "inside stays");
        // The label sits above the box and contains the class colour.
        let label_px = (0..60)
            .flat_map(|x| (10..20).map(move |y| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0 != [100, 100, 100])
            .count();
        assert!(label_px > 30, "{label_px}");
    }
}
