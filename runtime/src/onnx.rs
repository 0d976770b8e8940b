//! The ONNX Runtime executor (feature `onnx`): runs an exported detector — the two
//! graphs `backbone_rpn.onnx` and `roi_head.onnx` written by `frugal export` — through
//! `ort`, and returns the same [`Detection`]s as the tch model, using the same glue code
//! ([`crate::cnn`]).
//!
//! Opening checks everything before the first frame: both files exist and parse, their
//! inputs and outputs have the names, element types and shapes the glue expects, and
//! the `frugal.*` metadata is complete. Any problem is an [`OrtError`] naming the file.
//! Frames of another size than the export's are resized (bilinear) and the boxes
//! scaled back, so a reduced-resolution variant accepts full frames.
//!
//! The ONNX Runtime library is loaded at run time from `ORT_DYLIB_PATH` (ONNX Runtime
//! 1.31; `cargo xtask setup` provides it and `.cargo/config.toml` points there).

use crate::cnn::{self, DetectionParams, ProposalParams};
use crate::geom::{BBox, Detection, Detector, FrameRef};
use ort::session::Session;
use ort::value::{Tensor, TensorElementType, ValueType};
use std::format;
use std::path::{Path, PathBuf};
use std::string::{String, ToString};
use std::sync::OnceLock;
use std::time::Instant;
use std::vec;
use std::vec::Vec;

/// File name of the first graph in an export folder.
pub const BACKBONE_RPN_FILE: &str = "backbone_rpn.onnx";
/// File name of the second graph in an export folder.
pub const ROI_HEAD_FILE: &str = "roi_head.onnx";

/// Raw outputs of the `backbone_rpn` graph: `(features, objectness, deltas)`.
pub type BackboneOutputs = (Vec<f32>, Vec<f32>, Vec<f32>);

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

/// Where the ONNX Runtime library is: `ORT_DYLIB_PATH` when set (cargo sets it from
/// `.cargo/config.toml`); else the workspace's `.deps/onnxruntime/` seen from a binary
/// in `target/<profile>/` (or its `deps/`, `examples/`); else the system's
/// `libonnxruntime.so`.
fn library_path() -> String {
    if let Ok(path) = std::env::var("ORT_DYLIB_PATH") {
        return path;
    }
    let exe = std::env::current_exe().ok();
    let near_exe = exe.iter().flat_map(|exe| {
        exe.ancestors()
            .skip(2)
            .take(3)
            .map(|dir| dir.join(".deps/onnxruntime/libonnxruntime.so"))
            .collect::<Vec<_>>()
    });
    near_exe.into_iter().find(|p| p.is_file()).map_or_else(
        || "libonnxruntime.so".to_string(),
        |p| p.display().to_string(),
    )
}

/// The ONNX Runtime environment, created once per process (see [`library_path`]).
fn environment() -> Result<&'static ort::environment::Environment, OrtError> {
    static ENV: OnceLock<Result<ort::environment::Environment, (String, String)>> = OnceLock::new();
    let env = ENV.get_or_init(|| {
        let path = library_path();
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
        let anchors = cnn::anchors(
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
    pub fn run_backbone(&mut self, image: Vec<f32>) -> Result<BackboneOutputs, OrtError> {
        let shape = [1usize, 3, self.spec.height, self.spec.width];
        let err = Self::run_err(&self.files.0);
        let file = self.files.0.clone();
        let input = Tensor::from_array((shape, image)).map_err(&err)?;
        let out = self
            .backbone
            .run(ort::inputs!["image" => input])
            .map_err(&err)?;
        let get = |name: &str| -> Result<Vec<f32>, OrtError> {
            let value = out.get(name).ok_or_else(|| OrtError::Run {
                file: file.clone(),
                message: format!("no output `{name}`"),
            })?;
            Ok(value.try_extract_tensor::<f32>().map_err(&err)?.1.to_vec())
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
        let file = self.files.1.clone();
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
            let value = out.get(name).ok_or_else(|| OrtError::Run {
                file: file.clone(),
                message: format!("no output `{name}`"),
            })?;
            Ok(value.try_extract_tensor::<f32>().map_err(&err)?.1.to_vec())
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
            let small = cnn::resize_bilinear(frame, w, h);
            let resize_ms = t.elapsed().as_secs_f64() * 1e3;
            let resized = FrameRef::new(w, h, &small).ok_or(OrtError::FrameSize {
                got_w: frame.width,
                got_h: frame.height,
                want_w: w,
                want_h: h,
            })?;
            let (mut dets, mut times) = self.detect_timed(resized)?;
            times.preprocess_ms += resize_ms;
            cnn::rescale_detections(&mut dets, (w, h), (frame.width, frame.height));
            return Ok((dets, times));
        }
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        let mut times = StageTimes::default();
        let t = Instant::now();
        let image = cnn::normalize(frame, self.spec.pixel_mean, self.spec.pixel_std);
        times.preprocess_ms = ms(t);
        let t = Instant::now();
        let (features, objectness, deltas) = self.run_backbone(image)?;
        times.backbone_ms = ms(t);
        let t = Instant::now();
        let size = (w as f32, h as f32);
        let props = cnn::proposals(
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
        let dets = cnn::detections(&logits, &box_deltas, &props, size, self.spec.detections);
        times.detections_ms = ms(t);
        Ok((dets, times))
    }

    /// Detect signs in one frame, sorted by score (softmax probability, `[0, 1]`).
    pub fn detect(&mut self, frame: FrameRef<'_>) -> Result<Vec<Detection>, OrtError> {
        self.detect_timed(frame).map(|(d, _)| d)
    }
}

impl Detector for OrtDetector {
    type Error = OrtError;

    fn detect(&mut self, frame: FrameRef<'_>, out: &mut [Detection]) -> Result<usize, OrtError> {
        let dets = OrtDetector::detect(self, frame)?;
        let mut n = 0;
        for (slot, d) in out.iter_mut().zip(dets) {
            *slot = d;
            n += 1;
        }
        Ok(n)
    }
}
