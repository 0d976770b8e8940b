//! The network: a configurable conv backbone, the RPN head and the RoI head, all in one
//! named [`nn::VarStore`], plus [`FasterRcnn::detect`] gluing them with [`crate::glue`].
use crate::ModelError;
use crate::boxes;
use crate::config::ModelConfig;
use crate::glue::{self, ProposalParams};
use crate::roi_align::{RoiAlignParams, roi_align_gather};
use frugal_runtime::{BBox, Detection, Detector, FrameRef};
use std::path::Path;
use tch::{Device, Kind, Tensor, nn, nn::Module};

/// One layer of the network, for export and reporting.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct LayerInfo {
    /// VarStore path of the layer (`backbone.block2.conv0`).
    pub name: String,
    /// `conv3x3`, `conv1x1`, `linear`.
    pub kind: String,
    /// Input channels / features.
    pub inputs: i64,
    /// Output channels / features.
    pub outputs: i64,
    /// Stride (1 for linear layers).
    pub stride: i64,
    /// Weight shape.
    pub weight_shape: Vec<i64>,
}

/// The outputs of `backbone + rpn_head`.
pub struct RpnOutput {
    /// Feature map `[B, C, h, w]`.
    pub features: Tensor,
    /// Objectness logits `[B, A, h, w]`.
    pub objectness: Tensor,
    /// Box deltas `[B, 4A, h, w]`.
    pub deltas: Tensor,
}

/// The Faster-R-CNN-style detector.
pub struct FasterRcnn {
    vs: nn::VarStore,
    config: ModelConfig,
    blocks: Vec<Vec<nn::Conv2D>>,
    rpn_conv: nn::Conv2D,
    rpn_obj: nn::Conv2D,
    rpn_box: nn::Conv2D,
    fc1: nn::Linear,
    fc2: nn::Linear,
    cls: nn::Linear,
    bbox: nn::Linear,
}

fn conv(p: nn::Path<'_>, i: i64, o: i64, k: i64, stride: i64) -> nn::Conv2D {
    let c = nn::ConvConfig {
        stride,
        padding: k / 2,
        ..Default::default()
    };
    nn::conv2d(p, i, o, k, c)
}

impl FasterRcnn {
    /// A freshly initialised model on `device` (seed with `tch::manual_seed` first).
    pub fn new(config: ModelConfig, device: Device) -> Result<Self, ModelError> {
        config.validate("model config")?;
        let vs = nn::VarStore::new(device);
        let root = vs.root();
        let bb = &root / "backbone";
        let mut blocks = Vec::new();
        let mut ch = 3;
        for (i, b) in config.backbone.iter().enumerate() {
            let bp = &bb / format!("block{i}");
            let mut convs = Vec::new();
            for j in 0..b.convs {
                let stride = if j == 0 { b.stride } else { 1 };
                convs.push(conv(
                    &bp / format!("conv{j}"),
                    ch,
                    b.out_channels,
                    3,
                    stride,
                ));
                ch = b.out_channels;
            }
            blocks.push(convs);
        }
        let a = config.anchors_per_cell() as i64;
        let rp = &root / "rpn";
        let rpn_conv = conv(&rp / "conv", ch, config.rpn_channels, 3, 1);
        let small = |p: nn::Path<'_>, i, o| {
            let c = nn::ConvConfig {
                ws_init: nn::Init::Randn {
                    mean: 0.0,
                    stdev: 0.01,
                },
                bs_init: nn::Init::Const(0.0),
                ..Default::default()
            };
            nn::conv2d(p, i, o, 1, c)
        };
        let rpn_obj = small(&rp / "objectness", config.rpn_channels, a);
        let rpn_box = small(&rp / "deltas", config.rpn_channels, 4 * a);
        let rh = &root / "roi_head";
        let flat = ch * config.roi_size * config.roi_size;
        let fc1 = nn::linear(&rh / "fc1", flat, config.roi_hidden, Default::default());
        let fc2 = nn::linear(
            &rh / "fc2",
            config.roi_hidden,
            config.roi_hidden,
            Default::default(),
        );
        let lin = |p: nn::Path<'_>, i, o, sd| {
            let c = nn::LinearConfig {
                ws_init: nn::Init::Randn {
                    mean: 0.0,
                    stdev: sd,
                },
                bs_init: Some(nn::Init::Const(0.0)),
                bias: true,
            };
            nn::linear(p, i, o, c)
        };
        let k = config.num_classes as i64;
        let cls = lin(&rh / "class_logits", config.roi_hidden, k + 1, 0.01);
        let bbox = lin(&rh / "box_deltas", config.roi_hidden, 4 * k, 0.001);
        Ok(Self {
            vs,
            config,
            blocks,
            rpn_conv,
            rpn_obj,
            rpn_box,
            fc1,
            fc2,
            cls,
            bbox,
        })
    }

    /// The structure and pre/post-processing parameters.
    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// The weights (for saving, export, compression).
    pub fn var_store(&self) -> &nn::VarStore {
        &self.vs
    }

    /// The weights, mutable (for loading).
    pub fn var_store_mut(&mut self) -> &mut nn::VarStore {
        &mut self.vs
    }

    /// The device the weights live on.
    pub fn device(&self) -> Device {
        self.vs.device()
    }

    /// The RoIAlign attributes (equal to the ONNX `RoiAlign` node's).
    pub fn roi_align_params(&self) -> RoiAlignParams {
        RoiAlignParams {
            output_size: self.config.roi_size,
            sampling_ratio: self.config.roi_sampling_ratio,
            spatial_scale: 1.0 / self.config.stride() as f64,
        }
    }

    /// Every weighted layer, in forward order, with its shape.
    pub fn layers(&self) -> Vec<LayerInfo> {
        let mut out = Vec::new();
        let mut push_conv = |name: String, c: &nn::Conv2D, stride: i64| {
            let s = c.ws.size();
            out.push(LayerInfo {
                name,
                kind: format!("conv{}x{}", s[2], s[3]),
                inputs: s[1],
                outputs: s[0],
                stride,
                weight_shape: s,
            });
        };
        for (i, (b, bc)) in self.blocks.iter().zip(&self.config.backbone).enumerate() {
            for (j, c) in b.iter().enumerate() {
                push_conv(
                    format!("backbone.block{i}.conv{j}"),
                    c,
                    if j == 0 { bc.stride } else { 1 },
                );
            }
        }
        push_conv("rpn.conv".into(), &self.rpn_conv, 1);
        push_conv("rpn.objectness".into(), &self.rpn_obj, 1);
        push_conv("rpn.deltas".into(), &self.rpn_box, 1);
        for (name, l) in [
            ("roi_head.fc1", &self.fc1),
            ("roi_head.fc2", &self.fc2),
            ("roi_head.class_logits", &self.cls),
            ("roi_head.box_deltas", &self.bbox),
        ] {
            let s = l.ws.size();
            out.push(LayerInfo {
                name: name.into(),
                kind: "linear".into(),
                inputs: s[1],
                outputs: s[0],
                stride: 1,
                weight_shape: s,
            });
        }
        out
    }

    /// Network part 1: normalised images `[B, 3, H, W]` → features, objectness, deltas.
    pub fn backbone_rpn(&self, images: &Tensor) -> RpnOutput {
        self.backbone_rpn_as(images, Kind::Float)
    }

    /// [`FasterRcnn::backbone_rpn`] with its convolutions computed in `kind`
    /// (`Kind::BFloat16` for mixed-precision training): the input and each layer's
    /// weights are cast to `kind` on the way in, so the weights stay `f32` and so do
    /// their gradients; the outputs are `f32`. `Kind::Float` is the plain `f32` network.
    pub fn backbone_rpn_as(&self, images: &Tensor, kind: Kind) -> RpnOutput {
        let conv = |c: &nn::Conv2D, x: &Tensor, stride: i64| {
            if kind == Kind::Float {
                return c.forward(x);
            }
            let pad = c.ws.size()[2] / 2;
            x.conv2d(
                &c.ws.to_kind(kind),
                c.bs.as_ref().map(|b| b.to_kind(kind)).as_ref(),
                [stride, stride],
                [pad, pad],
                [1, 1],
                1,
            )
        };
        let mut x = images.to_kind(kind);
        for (b, bc) in self.blocks.iter().zip(&self.config.backbone) {
            for (j, c) in b.iter().enumerate() {
                x = conv(c, &x, if j == 0 { bc.stride } else { 1 }).relu();
            }
        }
        let h = conv(&self.rpn_conv, &x, 1).relu();
        RpnOutput {
            objectness: conv(&self.rpn_obj, &h, 1).to_kind(Kind::Float),
            deltas: conv(&self.rpn_box, &h, 1).to_kind(Kind::Float),
            features: x.to_kind(Kind::Float),
        }
    }

    /// Network part 2: features and RoIs (`[R, 4]` image pixels, with the image index
    /// of each) → class logits `[R, K+1]` and class-specific box deltas `[R, 4K]`.
    /// RoIAlign runs as [`roi_align_gather`] (same values as ONNX `RoiAlign`).
    pub fn roi_head(
        &self,
        features: &Tensor,
        rois: &Tensor,
        batch_indices: &[i64],
    ) -> (Tensor, Tensor) {
        let flat = Vec::<f32>::try_from(rois.detach().to_kind(Kind::Float).flatten(0, -1))
            .unwrap_or_default();
        let boxes: Vec<BBox> = flat
            .chunks_exact(4)
            .map(|c| BBox::new(c[0], c[1], c[2], c[3]))
            .collect();
        let pooled = roi_align_gather(features, &boxes, batch_indices, self.roi_align_params());
        let x = pooled
            .flatten(1, -1)
            .apply(&self.fc1)
            .relu()
            .apply(&self.fc2)
            .relu();
        (x.apply(&self.cls), x.apply(&self.bbox))
    }

    /// The anchors of an `height × width` image, in [`glue::proposals`] order.
    pub fn anchors(&self, height: usize, width: usize) -> (Vec<BBox>, (usize, usize)) {
        let (fh, fw) = glue::feature_size(&self.config, height, width);
        let a = boxes::anchors(
            fh,
            fw,
            self.config.stride() as f32,
            &self.config.anchor_sizes,
            &self.config.anchor_ratios,
        );
        (a, (fh, fw))
    }

    /// Normalised `[1, 3, H, W]` tensor of a frame.
    pub fn frame_tensor(&self, frame: FrameRef<'_>) -> Tensor {
        let v = glue::normalize(frame, self.config.pixel_mean, self.config.pixel_std);
        Tensor::from_slice(&v)
            .reshape([1, 3, i64::from(frame.height), i64::from(frame.width)])
            .to_device(self.device())
    }

    /// Proposal parameters for inference or training.
    pub fn proposal_params(&self, train: bool) -> ProposalParams {
        let c = &self.config;
        ProposalParams {
            pre_nms: if train {
                c.pre_nms_train
            } else {
                c.pre_nms_test
            },
            post_nms: if train {
                c.post_nms_train
            } else {
                c.post_nms_test
            },
            nms_iou: c.rpn_nms_iou,
            min_size: c.min_box_size,
        }
    }

    /// Proposals of image `b` of an [`RpnOutput`].
    pub fn proposals_of(
        &self,
        out: &RpnOutput,
        b: i64,
        img: (usize, usize),
        train: bool,
    ) -> Vec<BBox> {
        let (h, w) = img;
        let (anchors, fhw) = self.anchors(h, w);
        let obj = Vec::<f32>::try_from(
            out.objectness
                .get(b)
                .detach()
                .flatten(0, -1)
                .to_kind(Kind::Float),
        )
        .unwrap_or_default();
        let del = Vec::<f32>::try_from(
            out.deltas
                .get(b)
                .detach()
                .flatten(0, -1)
                .to_kind(Kind::Float),
        )
        .unwrap_or_default();
        glue::proposals(
            &obj,
            &del,
            fhw,
            &anchors,
            (w as f32, h as f32),
            self.proposal_params(train),
        )
    }

    /// Detect signs in one frame: detections sorted by score, highest first. The score
    /// is the softmax probability of the class, in `[0, 1]`.
    pub fn detect(&self, frame: FrameRef<'_>) -> Vec<Detection> {
        // a frame of another size than the model's input is resized to it (as the ONNX
        // executor does) and the boxes mapped back to the frame's pixels
        if let Some([w, h]) = self.config.input_size
            && (frame.width as usize, frame.height as usize) != (w, h)
        {
            let (w, h) = (w as u32, h as u32);
            let small = frugal_runtime::cnn::resize_bilinear(frame, w, h);
            let Some(resized) = FrameRef::new(w, h, &small) else {
                return Vec::new();
            };
            let mut dets = self.detect(resized);
            frugal_runtime::cnn::rescale_detections(&mut dets, (w, h), (frame.width, frame.height));
            return dets;
        }
        tch::no_grad(|| {
            let (h, w) = (frame.height as usize, frame.width as usize);
            let out = self.backbone_rpn(&self.frame_tensor(frame));
            let props = self.proposals_of(&out, 0, (h, w), false);
            if props.is_empty() {
                return Vec::new();
            }
            let rois = boxes_tensor(&props).to_device(self.device());
            let (logits, deltas) = self.roi_head(&out.features, &rois, &vec![0; props.len()]);
            let l = Vec::<f32>::try_from(logits.flatten(0, -1)).unwrap_or_default();
            let d = Vec::<f32>::try_from(deltas.flatten(0, -1)).unwrap_or_default();
            glue::detections(
                &l,
                &d,
                &props,
                (w as f32, h as f32),
                glue::detection_params(&self.config),
            )
        })
    }

    /// Save the weights as safetensors (temp file + rename).
    pub fn save(&self, path: &Path) -> Result<(), ModelError> {
        let tmp = path.with_file_name(format!(
            ".tmp-{}",
            path.file_name()
                .and_then(|n| n.to_str())
                .unwrap_or("model.safetensors")
        ));
        let tmp = if tmp.extension().is_some_and(|e| e == "safetensors") {
            tmp
        } else {
            tmp.with_extension("safetensors")
        };
        self.vs.save(&tmp).map_err(|e| ModelError::Torch {
            file: tmp.display().to_string(),
            msg: e.to_string(),
        })?;
        std::fs::rename(&tmp, path).map_err(|e| ModelError::io(path, e))
    }

    /// Load weights saved by [`FasterRcnn::save`]; every tensor must be present with
    /// the shape this config gives it, otherwise the error names the file and tensor.
    pub fn load_weights(&mut self, path: &Path) -> Result<(), ModelError> {
        let file = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|e| ModelError::io(path, e))?;
        let st =
            safetensors::SafeTensors::deserialize(&bytes).map_err(|e| ModelError::Checkpoint {
                file: file.clone(),
                msg: format!("not a safetensors file ({e})"),
            })?;
        let vars = self.vs.variables();
        let mut names: Vec<&String> = vars.keys().collect();
        names.sort();
        for name in names {
            let var = &vars[name];
            let view = st.tensor(name).map_err(|_| ModelError::Checkpoint {
                file: file.clone(),
                msg: format!(
                    "tensor `{name}` is missing (checkpoint of a different model structure?)"
                ),
            })?;
            let shape: Vec<i64> = view.shape().iter().map(|&s| s as i64).collect();
            if shape != var.size() {
                return Err(ModelError::Checkpoint {
                    file: file.clone(),
                    msg: format!(
                        "tensor `{name}` has shape {shape:?}, the config needs {:?}",
                        var.size()
                    ),
                });
            }
        }
        if let Some(extra) = st.names().into_iter().find(|n| !vars.contains_key(*n)) {
            return Err(ModelError::Checkpoint {
                file,
                msg: format!(
                    "unexpected tensor `{extra}` (checkpoint of a different model structure?)"
                ),
            });
        }
        self.vs.load(path).map_err(|e| ModelError::Torch {
            file,
            msg: e.to_string(),
        })
    }

    /// Load a model folder written by training: `config.json` + `best.safetensors`
    /// (or `checkpoint/model.safetensors` when no best model exists yet).
    pub fn load_dir(dir: &Path, device: Device) -> Result<Self, ModelError> {
        let cfg = crate::config::Config::load(&dir.join("config.json"))?;
        let mut m = Self::new(cfg.model, device)?;
        let best = dir.join("best.safetensors");
        let w = if best.exists() {
            best
        } else {
            dir.join("checkpoint").join("model.safetensors")
        };
        m.load_weights(&w)?;
        Ok(m)
    }
}

/// `[N, 4]` float tensor of boxes.
pub fn boxes_tensor(b: &[BBox]) -> Tensor {
    let flat: Vec<f32> = b.iter().flat_map(|b| [b.x1, b.y1, b.x2, b.y2]).collect();
    Tensor::from_slice(&flat).reshape([b.len() as i64, 4])
}

impl Detector for FasterRcnn {
    type Error = ModelError;

    fn detect(&mut self, frame: FrameRef<'_>, out: &mut [Detection]) -> Result<usize, ModelError> {
        let dets = FasterRcnn::detect(self, frame);
        let n = dets.len().min(out.len());
        out[..n].copy_from_slice(&dets[..n]);
        Ok(n)
    }
}
