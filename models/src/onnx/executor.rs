//! The ONNX Runtime executor: runs an exported detector (the two graphs of
//! [`super::export`]) through `ort` and returns the same [`Detection`]s as the tch
//! model, using the same glue code ([`crate::glue`]).
//!
//! Opening checks everything before the first frame: both files exist and parse, their
//! inputs and outputs have the names, element types and shapes the glue expects, and
//! the `frugal.*` metadata is complete. Any problem is an [`OrtError`] naming the file.

use super::export::{BACKBONE_RPN_FILE, ROI_HEAD_FILE};
use crate::boxes;
use crate::glue::{self, DetectionParams, ProposalParams};
use frugal_runtime::{BBox, Detection, Detector, FrameRef};
use ort::session::Session;
use ort::value::{Tensor, TensorElementType, ValueType};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Instant;

/// What can go wrong opening or running an exported detector.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OrtError {
    /// The ONNX Runtime library could not be loaded.
    #[error(
        "cannot load ONNX Runtime ({path}): {message}; run `cargo xtask setup` or set ORT_DYLIB_PATH"
    )]
    Library {
        /// The library path tried.
        path: String,
        /// Why it failed.
        message: String,
    },
    /// A model file is missing, unreadable, or not a valid ONNX model.
    #[error("{file}: {message}")]
    Model {
        /// The file.
        file: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The model's inputs, outputs or metadata are not what the executor expects.
    #[error("{file}: {message}")]
    Mismatch {
        /// The file.
        file: PathBuf,
        /// What does not match.
        message: String,
    },
    /// A frame is not the size the detector was exported for.
    #[error("frame is {got_w}×{got_h}, the detector was exported for {want_w}×{want_h}")]
    FrameSize {
        /// Frame width.
        got_w: u32,
        /// Frame height.
        got_h: u32,
        /// Expected width.
        want_w: u32,
        /// Expected height.
        want_h: u32,
    },
    /// ONNX Runtime failed while running a graph.
    #[error("{file}: inference failed: {message}")]
    Run {
        /// The graph's file.
        file: PathBuf,
        /// ONNX Runtime's message.
        message: String,
    },
}

/// The ONNX Runtime environment, created once per process from `ORT_DYLIB_PATH`.
fn environment() -> Result<&'static ort::environment::Environment, OrtError> {
    static ENV: OnceLock<Result<ort::environment::Environment, (String, String)>> = OnceLock::new();
    let env = ENV.get_or_init(|| {
        let path = std::env::var("ORT_DYLIB_PATH").unwrap_or_else(|_| "libonnxruntime.so".into());
        let builder = ort::init_from(&path).map_err(|e| (path.clone(), e.to_string()))?;
        builder
            .with_name("frugal")
            .build()
            .map_err(|e| (path, e.to_string()))
    });
    env.as_ref().map_err(|(path, message)| OrtError::Library {
        path: path.clone(),
        message: message.clone(),
    })
}

/// The glue parameters recorded in an exported graph's metadata.
#[derive(Clone, Debug, PartialEq)]
pub struct GlueSpec {
    /// Input frame height the graphs were exported for.
    pub height: usize,
    /// Input frame width.
    pub width: usize,
    /// Object classes `K`.
    pub num_classes: usize,
    /// Feature stride.
    pub stride: usize,
    /// Anchor sizes.
    pub anchor_sizes: Vec<f32>,
    /// Anchor ratios.
    pub anchor_ratios: Vec<f32>,
    /// Pixel normalisation mean.
    pub pixel_mean: [f32; 3],
    /// Pixel normalisation standard deviation.
    pub pixel_std: [f32; 3],
    /// Proposal parameters.
    pub proposals: ProposalParams,
    /// Detection parameters.
    pub detections: DetectionParams,
}

fn metadata(session: &Session, file: &Path) -> Result<GlueSpec, OrtError> {
    let meta = session.metadata().map_err(|e| OrtError::Model {
        file: file.into(),
        message: e.to_string(),
    })?;
    let get = |key: &str| -> Result<String, OrtError> {
        meta.custom(&format!("frugal.{key}"))
            .ok_or_else(|| OrtError::Mismatch {
                file: file.into(),
                message: format!(
                    "metadata key `frugal.{key}` is missing (not exported by frugal?)"
                ),
            })
    };
    let bad = |key: &str, v: &str| OrtError::Mismatch {
        file: file.into(),
        message: format!("metadata `frugal.{key}` = `{v}` is not valid"),
    };
    let num = |key: &str| -> Result<usize, OrtError> {
        let v = get(key)?;
        v.parse().map_err(|_| bad(key, &v))
    };
    let float = |key: &str| -> Result<f32, OrtError> {
        let v = get(key)?;
        v.parse().map_err(|_| bad(key, &v))
    };
    let floats = |key: &str| -> Result<Vec<f32>, OrtError> {
        let v = get(key)?;
        v.split(',')
            .map(|s| s.parse::<f32>().map_err(|_| bad(key, &v)))
            .collect()
    };
    let three = |key: &str| -> Result<[f32; 3], OrtError> {
        let v = floats(key)?;
        <[f32; 3]>::try_from(v.as_slice()).map_err(|_| bad(key, &format!("{v:?}")))
    };
    let format = get("format")?;
    if format != "faster-rcnn-split/1" {
        return Err(bad("format", &format));
    }
    Ok(GlueSpec {
        height: num("input_height")?,
        width: num("input_width")?,
        num_classes: num("num_classes")?,
        stride: num("stride")?,
        anchor_sizes: floats("anchor_sizes")?,
        anchor_ratios: floats("anchor_ratios")?,
        pixel_mean: three("pixel_mean")?,
        pixel_std: three("pixel_std")?,
        proposals: ProposalParams {
            pre_nms: num("pre_nms")?,
            post_nms: num("post_nms")?,
            nms_iou: float("rpn_nms_iou")?,
            min_size: float("min_box_size")?,
        },
        detections: DetectionParams {
            num_classes: num("num_classes")?,
            score_threshold: float("score_threshold")?,
            nms_iou: float("nms_iou")?,
            max_detections: num("max_detections")?,
        },
    })
}

/// Check a session's inputs or outputs: names, element types and fixed dimensions
/// (`-1` in `want` accepts any size).
fn check_outlets(
    file: &Path,
    what: &str,
    outlets: &[ort::value::Outlet],
    want: &[(&str, TensorElementType, Vec<i64>)],
) -> Result<(), OrtError> {
    let names: Vec<&str> = outlets.iter().map(|o| o.name()).collect();
    let want_names: Vec<&str> = want.iter().map(|w| w.0).collect();
    if names != want_names {
        return Err(OrtError::Mismatch {
            file: file.into(),
            message: format!("{what} are {names:?}, expected {want_names:?}"),
        });
    }
    for (o, (name, ty, dims)) in outlets.iter().zip(want) {
        let ok = match o.dtype() {
            ValueType::Tensor { ty: t, shape, .. } => {
                t == ty
                    && shape.len() == dims.len()
                    && shape.iter().zip(dims).all(|(s, d)| *d == -1 || s == d)
            }
            _ => false,
        };
        if !ok {
            return Err(OrtError::Mismatch {
                file: file.into(),
                message: format!(
                    "{what} `{name}` is {:?}, expected {ty:?} tensor of shape {dims:?}",
                    o.dtype()
                ),
            });
        }
    }
    Ok(())
}

/// Time spent in each part of the last [`OrtDetector::detect_timed`] call.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimes {
    /// Normalisation of the frame.
    pub preprocess_ms: f64,
    /// The `backbone_rpn` graph.
    pub backbone_ms: f64,
    /// Proposal decoding and NMS in Rust.
    pub proposals_ms: f64,
    /// The `roi_head` graph.
    pub head_ms: f64,
    /// Detection decoding and per-class NMS in Rust.
    pub detections_ms: f64,
}

/// An exported detector running in ONNX Runtime.
pub struct OrtDetector {
    backbone: Session,
    head: Session,
    files: (PathBuf, PathBuf),
    spec: GlueSpec,
    anchors: Vec<BBox>,
    feature_hw: (usize, usize),
    feature_channels: usize,
}

impl std::fmt::Debug for OrtDetector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OrtDetector")
            .field("files", &self.files)
            .field("spec", &self.spec)
            .finish()
    }
}

fn open(file: &Path, threads: usize) -> Result<Session, OrtError> {
    let env = environment()?;
    if !file.is_file() {
        return Err(OrtError::Model {
            file: file.into(),
            message: "no such file".into(),
        });
    }
    let model_err = |e: String| OrtError::Model {
        file: file.into(),
        message: e,
    };
    let bytes = std::fs::read(file).map_err(|e| model_err(e.to_string()))?;
    Session::builder(env)
        .map_err(|e| model_err(e.to_string()))?
        .with_intra_threads(threads.max(1))
        .map_err(|e| model_err(e.to_string()))?
        .with_inter_threads(1)
        .map_err(|e| model_err(e.to_string()))?
        .commit_from_memory(&bytes)
        .map_err(|e| model_err(format!("not a loadable ONNX model: {e}")))
}

impl OrtDetector {
    /// Open the two graphs in `dir` with `threads` intra-op threads.
    pub fn open(dir: &Path, threads: usize) -> Result<Self, OrtError> {
        let f1 = dir.join(BACKBONE_RPN_FILE);
        let f2 = dir.join(ROI_HEAD_FILE);
        let backbone = open(&f1, threads)?;
        let head = open(&f2, threads)?;
        let spec = metadata(&backbone, &f1)?;
        let spec2 = metadata(&head, &f2)?;
        if spec != spec2 {
            return Err(OrtError::Mismatch {
                file: f2,
                message: format!(
                    "its metadata differs from {}'s: not exported together",
                    f1.display()
                ),
            });
        }
        let (h, w) = (spec.height as i64, spec.width as i64);
        let f32t = TensorElementType::Float32;
        check_outlets(
            &f1,
            "inputs",
            backbone.inputs(),
            &[("image", f32t, vec![1, 3, h, w])],
        )?;
        let a = (spec.anchor_sizes.len() * spec.anchor_ratios.len()) as i64;
        check_outlets(
            &f1,
            "outputs",
            backbone.outputs(),
            &[
                ("features", f32t, vec![1, -1, -1, -1]),
                ("objectness", f32t, vec![1, a, -1, -1]),
                ("deltas", f32t, vec![1, 4 * a, -1, -1]),
            ],
        )?;
        let feature_dims = match backbone.outputs().first().map(|o| o.dtype()) {
            Some(ValueType::Tensor { shape, .. }) => shape.to_vec(),
            _ => Vec::new(),
        };
        let [_, c, fh, fw] =
            <[i64; 4]>::try_from(feature_dims.as_slice()).map_err(|_| OrtError::Mismatch {
                file: f1.clone(),
                message: "output `features` has no fixed 4-D shape".into(),
            })?;
        let k = spec.num_classes as i64;
        check_outlets(
            &f2,
            "inputs",
            head.inputs(),
            &[
                ("features", f32t, vec![1, c, fh, fw]),
                ("rois", f32t, vec![-1, 4]),
                ("batch_indices", TensorElementType::Int64, vec![-1]),
            ],
        )?;
        check_outlets(
            &f2,
            "outputs",
            head.outputs(),
            &[
                ("class_logits", f32t, vec![-1, k + 1]),
                ("box_deltas", f32t, vec![-1, 4 * k]),
            ],
        )?;
        let feature_hw = (fh as usize, fw as usize);
        let anchors = boxes::anchors(
            feature_hw.0,
            feature_hw.1,
            spec.stride as f32,
            &spec.anchor_sizes,
            &spec.anchor_ratios,
        );
        Ok(Self {
            backbone,
            head,
            files: (f1, f2),
            spec,
            anchors,
            feature_hw,
            feature_channels: c as usize,
        })
    }

    /// The glue parameters read from the graphs.
    pub fn spec(&self) -> &GlueSpec {
        &self.spec
    }

    fn run_err(file: &Path) -> impl Fn(ort::Error) -> OrtError + '_ {
        move |e| OrtError::Run {
            file: file.into(),
            message: e.to_string(),
        }
    }

    /// Run `backbone_rpn` on a normalised `[1, 3, H, W]` image; returns
    /// `(features, objectness, deltas)` flattened.
    pub fn run_backbone(
        &mut self,
        image: Vec<f32>,
    ) -> Result<(Vec<f32>, Vec<f32>, Vec<f32>), OrtError> {
        let shape = [1usize, 3, self.spec.height, self.spec.width];
        let err = Self::run_err(&self.files.0);
        let input = Tensor::from_array((shape, image)).map_err(&err)?;
        let out = self
            .backbone
            .run(ort::inputs!["image" => input])
            .map_err(&err)?;
        let get = |name: &str| -> Result<Vec<f32>, OrtError> {
            Ok(out[name]
                .try_extract_tensor::<f32>()
                .map_err(&err)?
                .1
                .to_vec())
        };
        Ok((get("features")?, get("objectness")?, get("deltas")?))
    }

    /// Run `roi_head` on features and RoIs; returns `(class_logits, box_deltas)`.
    pub fn run_head(
        &mut self,
        features: Vec<f32>,
        rois: &[BBox],
    ) -> Result<(Vec<f32>, Vec<f32>), OrtError> {
        let err = Self::run_err(&self.files.1);
        let (fh, fw) = self.feature_hw;
        let f = Tensor::from_array(([1usize, self.feature_channels, fh, fw], features))
            .map_err(&err)?;
        let flat: Vec<f32> = rois.iter().flat_map(|b| [b.x1, b.y1, b.x2, b.y2]).collect();
        let r = Tensor::from_array(([rois.len(), 4usize], flat)).map_err(&err)?;
        let bi = Tensor::from_array(([rois.len()], vec![0i64; rois.len()])).map_err(&err)?;
        let out = self
            .head
            .run(ort::inputs!["features" => f, "rois" => r, "batch_indices" => bi])
            .map_err(&err)?;
        let get = |name: &str| -> Result<Vec<f32>, OrtError> {
            Ok(out[name]
                .try_extract_tensor::<f32>()
                .map_err(&err)?
                .1
                .to_vec())
        };
        Ok((get("class_logits")?, get("box_deltas")?))
    }

    /// Detect signs in one frame (sorted by score), with the time of each stage.
    pub fn detect_timed(
        &mut self,
        frame: FrameRef<'_>,
    ) -> Result<(Vec<Detection>, StageTimes), OrtError> {
        let (w, h) = (self.spec.width as u32, self.spec.height as u32);
        if frame.width == 0 || frame.height == 0 {
            return Err(OrtError::FrameSize {
                got_w: frame.width,
                got_h: frame.height,
                want_w: w,
                want_h: h,
            });
        }
        // frames of another size are resized (bilinear) to the exported input size,
        // and the boxes scaled back to the frame's pixels
        if (frame.width, frame.height) != (w, h) {
            let t = Instant::now();
            let small = resize_bilinear(frame, w, h);
            let resize_ms = t.elapsed().as_secs_f64() * 1e3;
            let resized = FrameRef::new(w, h, &small).ok_or_else(|| OrtError::FrameSize {
                got_w: frame.width,
                got_h: frame.height,
                want_w: w,
                want_h: h,
            })?;
            let (mut dets, mut times) = self.detect_timed(resized)?;
            times.preprocess_ms += resize_ms;
            let (sx, sy) = (
                frame.width as f32 / w as f32,
                frame.height as f32 / h as f32,
            );
            let (fw, fh) = (frame.width as f32, frame.height as f32);
            for d in &mut dets {
                let b = d.bbox;
                d.bbox = BBox::new(
                    (b.x1 * sx).clamp(0.0, fw),
                    (b.y1 * sy).clamp(0.0, fh),
                    (b.x2 * sx).clamp(0.0, fw),
                    (b.y2 * sy).clamp(0.0, fh),
                );
            }
            return Ok((dets, times));
        }
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        let mut times = StageTimes::default();
        let t = Instant::now();
        let image = glue::normalize(frame, self.spec.pixel_mean, self.spec.pixel_std);
        times.preprocess_ms = ms(t);
        let t = Instant::now();
        let (features, objectness, deltas) = self.run_backbone(image)?;
        times.backbone_ms = ms(t);
        let t = Instant::now();
        let size = (w as f32, h as f32);
        let props = glue::proposals(
            &objectness,
            &deltas,
            self.feature_hw,
            &self.anchors,
            size,
            self.spec.proposals,
        );
        times.proposals_ms = ms(t);
        if props.is_empty() {
            return Ok((Vec::new(), times));
        }
        let t = Instant::now();
        let (logits, box_deltas) = self.run_head(features, &props)?;
        times.head_ms = ms(t);
        let t = Instant::now();
        let dets = glue::detections(&logits, &box_deltas, &props, size, self.spec.detections);
        times.detections_ms = ms(t);
        Ok((dets, times))
    }

    /// Detect signs in one frame, sorted by score (softmax probability, `[0, 1]`).
    pub fn detect(&mut self, frame: FrameRef<'_>) -> Result<Vec<Detection>, OrtError> {
        self.detect_timed(frame).map(|(d, _)| d)
    }
}

/// Resize an RGB8 frame to `w × h` with bilinear interpolation (pixel centres aligned,
/// as `align_corners = false`).
pub fn resize_bilinear(frame: FrameRef<'_>, w: u32, h: u32) -> Vec<u8> {
    let (sw, sh) = (frame.width as usize, frame.height as usize);
    let (dw, dh) = (w as usize, h as usize);
    let (fx, fy) = (sw as f32 / dw as f32, sh as f32 / dh as f32);
    let axis = |d: usize, f: f32, n: usize| {
        let s = ((d as f32 + 0.5) * f - 0.5).max(0.0);
        let i0 = (s.floor() as usize).min(n - 1);
        let i1 = (i0 + 1).min(n - 1);
        (i0, i1, s - i0 as f32)
    };
    let xs: Vec<_> = (0..dw).map(|x| axis(x, fx, sw)).collect();
    let mut out = Vec::with_capacity(dw * dh * 3);
    for y in 0..dh {
        let (y0, y1, ty) = axis(y, fy, sh);
        let r0 = &frame.rgb[y0 * sw * 3..(y0 + 1) * sw * 3];
        let r1 = &frame.rgb[y1 * sw * 3..(y1 + 1) * sw * 3];
        for &(x0, x1, tx) in &xs {
            for c in 0..3 {
                let p = |r: &[u8], x: usize| f32::from(r[x * 3 + c]);
                let top = p(r0, x0) + (p(r0, x1) - p(r0, x0)) * tx;
                let bot = p(r1, x0) + (p(r1, x1) - p(r1, x0)) * tx;
                out.push((top + (bot - top) * ty).round().clamp(0.0, 255.0) as u8);
            }
        }
    }
    out
}

impl Detector for OrtDetector {
    type Error = OrtError;

    fn detect(&mut self, frame: FrameRef<'_>, out: &mut [Detection]) -> Result<usize, OrtError> {
        let dets = OrtDetector::detect(self, frame)?;
        let n = dets.len().min(out.len());
        out[..n].copy_from_slice(&dets[..n]);
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::FasterRcnn;
    use crate::config::{BlockConfig, ModelConfig};
    use crate::onnx::export_detector;

    fn tiny(seed: i64) -> FasterRcnn {
        tch::manual_seed(seed);
        let cfg = ModelConfig {
            num_classes: 3,
            backbone: vec![
                BlockConfig {
                    out_channels: 8,
                    stride: 2,
                    convs: 1,
                },
                BlockConfig {
                    out_channels: 16,
                    stride: 2,
                    convs: 1,
                },
            ],
            rpn_channels: 8,
            roi_hidden: 32,
            ..ModelConfig::default()
        };
        FasterRcnn::new(cfg, tch::Device::Cpu).unwrap()
    }

    /// A deterministic frame with some structure (gradients and a bright square).
    fn frame(w: u32, h: u32, k: u32) -> Vec<u8> {
        let mut px = Vec::with_capacity((w * h * 3) as usize);
        for y in 0..h {
            for x in 0..w {
                let inside = (x + k * 3) % w > 10 && (x + k * 3) % w < 26 && y > 8 && y < 24;
                let v = if inside {
                    240
                } else {
                    ((x * 7 + y * 3 + k * 11) % 200) as u8 as u32
                };
                px.extend([v as u8, (v / 2) as u8, (255 - v) as u8]);
            }
        }
        px
    }

    #[test]
    fn ort_executor_matches_tch_raw_outputs_and_detections() {
        let model = tiny(11);
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (64u32, 48u32);
        export_detector(&model, h as usize, w as usize, dir.path()).unwrap();
        let mut ort = OrtDetector::open(dir.path(), 1).unwrap();
        assert_eq!(ort.spec().num_classes, 3);
        let frames: Vec<_> = (0..6).map(|k| (w, h, frame(w, h, k))).collect();
        let r = crate::onnx::parity(&model, &mut ort, &frames).unwrap();
        assert_eq!(r.frames, 6);
        assert!(
            r.max_raw_diff < 1e-4,
            "raw outputs differ by {}",
            r.max_raw_diff
        );
        assert!(
            r.tch_detections > 0,
            "no detections to compare: make the test frames richer"
        );
        assert!(r.agrees(1e-4), "{r:?}");
    }

    #[test]
    fn bad_files_give_clear_errors() {
        let model = tiny(5);
        let dir = tempfile::tempdir().unwrap();
        let files = export_detector(&model, 32, 32, dir.path()).unwrap();
        let msg =
            |r: Result<OrtDetector, OrtError>| r.err().map(|e| e.to_string()).unwrap_or_default();

        // a frame with no pixels
        let mut ok = OrtDetector::open(dir.path(), 1).unwrap();
        if let Some(empty) = FrameRef::new(0, 32, &[]) {
            let e = ok.detect(empty).unwrap_err().to_string();
            assert!(e.contains("0×32") && e.contains("32×32"), "{e}");
        }
        // a frame of another size is resized, not refused
        let px = vec![0u8; 40 * 32 * 3];
        assert!(ok.detect(FrameRef::new(40, 32, &px).unwrap()).is_ok());

        // missing file
        let empty = tempfile::tempdir().unwrap();
        let e = msg(OrtDetector::open(empty.path(), 1));
        assert!(
            e.contains(BACKBONE_RPN_FILE) && e.contains("no such file"),
            "{e}"
        );

        // truncated file
        let bytes = std::fs::read(&files.roi_head).unwrap();
        std::fs::write(&files.roi_head, &bytes[..bytes.len() / 2]).unwrap();
        let e = msg(OrtDetector::open(dir.path(), 1));
        assert!(
            e.contains(ROI_HEAD_FILE) && e.contains("not a loadable ONNX model"),
            "{e}"
        );

        // not ONNX at all
        std::fs::write(&files.roi_head, b"this is not a protobuf").unwrap();
        let e = msg(OrtDetector::open(dir.path(), 1));
        assert!(e.contains(ROI_HEAD_FILE), "{e}");

        // a valid ONNX file whose inputs do not match: the backbone graph in the head's place
        std::fs::copy(&files.backbone_rpn, &files.roi_head).unwrap();
        let e = msg(OrtDetector::open(dir.path(), 1));
        assert!(e.contains("inputs are [\"image\"]"), "{e}");

        // graphs from two different exports (metadata differs)
        let other = tempfile::tempdir().unwrap();
        let f2 = export_detector(&model, 48, 32, other.path()).unwrap();
        std::fs::copy(&f2.roi_head, &files.roi_head).unwrap();
        let e = msg(OrtDetector::open(dir.path(), 1));
        assert!(e.contains("not exported together"), "{e}");
    }
}
