//! Pruning: global magnitude pruning (masks), structured channel pruning (physically
//! smaller layers) and layer (block) removal.
use crate::config::ModelConfig;
use crate::{FasterRcnn, ModelError};
use std::collections::HashMap;
use tch::{Device, Kind, Tensor};

fn torch_err(what: &str) -> impl Fn(tch::TchError) -> ModelError + '_ {
    move |e| ModelError::Torch {
        file: what.into(),
        msg: e.to_string(),
    }
}

/// Zero masks of a magnitude-pruned model: weight name → `{0, 1}` float tensor.
pub type Masks = HashMap<String, Tensor>;

/// The prunable weights: every conv and FC weight (biases excluded).
pub fn prunable_weights(model: &FasterRcnn) -> Vec<String> {
    model
        .layers()
        .into_iter()
        .map(|l| format!("{}.weight", l.name))
        .collect()
}

/// Global magnitude pruning: zero exactly `round(sparsity · N)` of the `N` conv and FC
/// weights, those of smallest magnitude over all layers together (ties broken by
/// position). Returns the masks (1 = kept) to re-apply after every optimizer step.
pub fn magnitude_prune(model: &FasterRcnn, sparsity: f64) -> Result<Masks, ModelError> {
    if !(0.0..1.0).contains(&sparsity) {
        return Err(ModelError::Config {
            file: "compress grid".into(),
            msg: format!("sparsity must be in [0, 1), got {sparsity}"),
        });
    }
    let vars = model.var_store().variables();
    let names = prunable_weights(model);
    let mut flat = Vec::new();
    for n in &names {
        let t = vars.get(n).ok_or_else(|| ModelError::Config {
            file: "model".into(),
            msg: format!("no tensor `{n}`"),
        })?;
        flat.push(t.detach().abs().flatten(0, -1));
    }
    let all = Tensor::cat(&flat, 0);
    let n = all.size()[0];
    let k = (sparsity * n as f64).round() as i64;
    // positions of the k smallest magnitudes (stable sort: ties by position)
    let order = all.argsort_stable(true, 0, false);
    let mut keep = Tensor::ones([n], (Kind::Float, Device::Cpu));
    if k > 0 {
        let _ = keep
            .f_index_fill_(0, &order.narrow(0, 0, k), 0.0)
            .map_err(torch_err("magnitude pruning"))?;
    }
    let mut masks = Masks::new();
    let mut off = 0;
    for (name, f) in names.iter().zip(&flat) {
        let len = f.size()[0];
        let t = &vars[name];
        masks.insert(name.clone(), keep.narrow(0, off, len).reshape(t.size()));
        off += len;
    }
    apply_masks(model, &masks);
    Ok(masks)
}

/// Multiply every masked weight by its mask (in place).
pub fn apply_masks(model: &FasterRcnn, masks: &Masks) {
    let vars = model.var_store().variables();
    tch::no_grad(|| {
        for (name, m) in masks {
            if let Some(t) = vars.get(name) {
                let mut t = t.shallow_clone();
                t *= m;
            }
        }
    });
}

/// Fraction of exactly-zero values among the prunable weights.
pub fn sparsity(model: &FasterRcnn) -> f64 {
    let vars = model.var_store().variables();
    let (mut zeros, mut total) = (0i64, 0i64);
    for n in prunable_weights(model) {
        if let Some(t) = vars.get(&n) {
            zeros += t.eq(0.0).sum(Kind::Int64).int64_value(&[]);
            total += t.numel() as i64;
        }
    }
    zeros as f64 / total.max(1) as f64
}

/// Number of parameters (weights and biases).
pub fn parameter_count(model: &FasterRcnn) -> usize {
    model
        .var_store()
        .variables()
        .values()
        .map(|t| t.numel())
        .sum()
}

/// The output channels kept by structured pruning, per layer name.
pub type Kept = HashMap<String, Vec<i64>>;

/// The `k` output channels of a `[O, …]` weight with the largest L1 norms, ascending.
fn top_l1(w: &Tensor, k: i64) -> Vec<i64> {
    let norms = w
        .detach()
        .abs()
        .flatten(1, -1)
        .sum_dim_intlist(1, false, Kind::Float);
    let idx = norms.argsort_stable(true, 0, true).narrow(0, 0, k);
    let mut v = Vec::<i64>::try_from(idx).unwrap_or_default();
    v.sort_unstable();
    v
}

fn keep_count(n: i64, keep: f64) -> i64 {
    ((n as f64 * keep).round() as i64).clamp(1, n)
}

/// Copy `src` into the model's tensor `name` (shapes must agree).
fn set(model: &FasterRcnn, name: &str, src: &Tensor) -> Result<(), ModelError> {
    let vars = model.var_store().variables();
    let t = vars.get(name).ok_or_else(|| ModelError::Config {
        file: "model".into(),
        msg: format!("no tensor `{name}`"),
    })?;
    if t.size() != src.size() {
        return Err(ModelError::Config {
            file: "model".into(),
            msg: format!(
                "tensor `{name}`: shape {:?} cannot take {:?}",
                t.size(),
                src.size()
            ),
        });
    }
    tch::no_grad(|| t.shallow_clone().copy_(src));
    Ok(())
}

fn idx(v: &[i64]) -> Tensor {
    Tensor::from_slice(v)
}

/// Structured channel pruning: keep the fraction `keep` of the output channels (the
/// filters of largest L1 norm) of every backbone conv, of the RPN's 3×3 conv and of the
/// two hidden FC layers, and rebuild a physically smaller model whose next layers read
/// only the kept channels (including the RPN conv's and `roi_head.fc1`'s inputs, where
/// each feature channel is `roi_size²` columns). Returns the model and the kept channels.
pub fn prune_channels(model: &FasterRcnn, keep: f64) -> Result<(FasterRcnn, Kept), ModelError> {
    if !(keep > 0.0 && keep <= 1.0) {
        return Err(ModelError::Config {
            file: "compress grid".into(),
            msg: format!("channel keep fraction must be in (0, 1], got {keep}"),
        });
    }
    let vars = model.var_store().variables();
    let cfg = model.config().clone();
    let w = |n: &str| vars[&format!("{n}.weight")].detach();
    let b = |n: &str| vars[&format!("{n}.bias")].detach();
    let mut kept = Kept::new();
    let mut new_cfg = cfg.clone();
    let mut convs = Vec::new();
    for (i, blk) in cfg.backbone.iter().enumerate() {
        let k = keep_count(blk.out_channels, keep);
        new_cfg.backbone[i].out_channels = k;
        for j in 0..blk.convs {
            let name = format!("backbone.block{i}.conv{j}");
            kept.insert(name.clone(), top_l1(&w(&name), k));
            convs.push(name);
        }
    }
    new_cfg.rpn_channels = keep_count(cfg.rpn_channels, keep);
    kept.insert(
        "rpn.conv".into(),
        top_l1(&w("rpn.conv"), new_cfg.rpn_channels),
    );
    new_cfg.roi_hidden = keep_count(cfg.roi_hidden, keep);
    for l in ["roi_head.fc1", "roi_head.fc2"] {
        kept.insert(l.into(), top_l1(&w(l), new_cfg.roi_hidden));
    }
    let pruned = FasterRcnn::new(new_cfg.clone(), model.device())?;
    let all_in = |n: i64| (0..n).collect::<Vec<i64>>();
    // backbone chain
    let mut prev: Vec<i64> = all_in(3);
    for name in &convs {
        let out = &kept[name];
        let wt = w(name)
            .index_select(0, &idx(out))
            .index_select(1, &idx(&prev));
        set(&pruned, &format!("{name}.weight"), &wt)?;
        set(
            &pruned,
            &format!("{name}.bias"),
            &b(name).index_select(0, &idx(out)),
        )?;
        prev = out.clone();
    }
    let feat = prev;
    let rk = &kept["rpn.conv"];
    let wt = w("rpn.conv")
        .index_select(0, &idx(rk))
        .index_select(1, &idx(&feat));
    set(&pruned, "rpn.conv.weight", &wt)?;
    set(
        &pruned,
        "rpn.conv.bias",
        &b("rpn.conv").index_select(0, &idx(rk)),
    )?;
    for l in ["rpn.objectness", "rpn.deltas"] {
        set(
            &pruned,
            &format!("{l}.weight"),
            &w(l).index_select(1, &idx(rk)),
        )?;
        set(&pruned, &format!("{l}.bias"), &b(l))?;
    }
    let cells = cfg.roi_size * cfg.roi_size;
    let cols: Vec<i64> = feat
        .iter()
        .flat_map(|c| (c * cells)..((c + 1) * cells))
        .collect();
    let h1 = &kept["roi_head.fc1"];
    let h2 = &kept["roi_head.fc2"];
    let fc1 = w("roi_head.fc1")
        .index_select(0, &idx(h1))
        .index_select(1, &idx(&cols));
    set(&pruned, "roi_head.fc1.weight", &fc1)?;
    set(
        &pruned,
        "roi_head.fc1.bias",
        &b("roi_head.fc1").index_select(0, &idx(h1)),
    )?;
    let fc2 = w("roi_head.fc2")
        .index_select(0, &idx(h2))
        .index_select(1, &idx(h1));
    set(&pruned, "roi_head.fc2.weight", &fc2)?;
    set(
        &pruned,
        "roi_head.fc2.bias",
        &b("roi_head.fc2").index_select(0, &idx(h2)),
    )?;
    for l in ["roi_head.class_logits", "roi_head.box_deltas"] {
        set(
            &pruned,
            &format!("{l}.weight"),
            &w(l).index_select(1, &idx(h2)),
        )?;
        set(&pruned, &format!("{l}.bias"), &b(l))?;
    }
    Ok((pruned, kept))
}

/// Layer removal: drop the backbone blocks listed in `blocks`. Layers whose shapes are
/// unchanged keep their weights; the layer right after a removed block (and the RPN
/// conv and `roi_head.fc1` when the feature channels change) is freshly initialised,
/// so the result needs fine-tuning. The feature stride follows the remaining blocks.
pub fn drop_blocks(model: &FasterRcnn, blocks: &[usize]) -> Result<FasterRcnn, ModelError> {
    let cfg = model.config();
    if blocks.iter().any(|&b| b >= cfg.backbone.len()) || blocks.len() >= cfg.backbone.len() {
        return Err(ModelError::Config {
            file: "compress grid".into(),
            msg: format!(
                "cannot drop blocks {blocks:?} of a {}-block backbone (at least one must remain)",
                cfg.backbone.len()
            ),
        });
    }
    let mut new_cfg: ModelConfig = cfg.clone();
    new_cfg.backbone = cfg
        .backbone
        .iter()
        .enumerate()
        .filter(|(i, _)| !blocks.contains(i))
        .map(|(_, b)| b.clone())
        .collect();
    // map new block index → old block index
    let old_of: Vec<usize> = (0..cfg.backbone.len())
        .filter(|i| !blocks.contains(i))
        .collect();
    let new = FasterRcnn::new(new_cfg, model.device())?;
    let src = model.var_store().variables();
    let dst = new.var_store().variables();
    for (name, t) in &dst {
        let from = match name.strip_prefix("backbone.block") {
            Some(rest) => {
                let (i, tail) = rest.split_once('.').unwrap_or((rest, ""));
                let i: usize = i.parse().unwrap_or(usize::MAX);
                old_of.get(i).map(|o| format!("backbone.block{o}.{tail}"))
            }
            None => Some(name.clone()),
        };
        if let Some(s) = from.and_then(|f| src.get(&f))
            && s.size() == t.size()
        {
            tch::no_grad(|| t.shallow_clone().copy_(s));
        }
    }
    Ok(new)
}

/// The same weights under another config of the same structure (for the glue
/// parameters: proposal counts, thresholds).
pub fn with_config(model: &FasterRcnn, cfg: ModelConfig) -> Result<FasterRcnn, ModelError> {
    let new = FasterRcnn::new(cfg, model.device())?;
    for (name, t) in model.var_store().variables() {
        set(&new, &name, &t.detach())?;
    }
    Ok(new)
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn tiny(seed: i64) -> FasterRcnn {
        let m = crate::testing::tiny_model(seed, &[(8, 2, 1), (16, 2, 2), (12, 1, 1)]);
        // non-zero biases so that zeroed filters matter
        for (n, t) in m.var_store().variables() {
            if n.ends_with(".bias") {
                tch::no_grad(|| t.shallow_clone().copy_(&(t.randn_like() * 0.1)));
            }
        }
        m
    }

    #[test]
    fn magnitude_pruning_reaches_the_exact_sparsity_and_keeps_the_largest() {
        for s in [0.3, 0.5, 0.7, 0.9] {
            let m = tiny(1);
            let before: Vec<f32> = prunable_weights(&m)
                .iter()
                .flat_map(|n| {
                    Vec::<f32>::try_from(m.var_store().variables()[n].abs().flatten(0, -1)).unwrap()
                })
                .collect();
            let masks = magnitude_prune(&m, s).unwrap();
            let n = before.len() as f64;
            let got = sparsity(&m);
            assert!(
                (got - (s * n).round() / n).abs() < 1e-12,
                "asked {s}, got {got}"
            );
            let kept: f64 = masks
                .values()
                .map(|t| t.sum(Kind::Float).double_value(&[]))
                .sum();
            assert_eq!(kept as usize, before.len() - (s * n).round() as usize);
            // every surviving weight is at least as large as every pruned one
            let mut sorted = before.clone();
            sorted.sort_by(f32::total_cmp);
            let thr = sorted[(s * n).round() as usize - 1];
            let after: Vec<f32> = prunable_weights(&m)
                .iter()
                .flat_map(|n| {
                    Vec::<f32>::try_from(m.var_store().variables()[n].abs().flatten(0, -1)).unwrap()
                })
                .collect();
            assert!(after.iter().all(|v| *v == 0.0 || *v >= thr));
        }
        assert!(magnitude_prune(&tiny(1), 1.0).is_err());
    }

    #[test]
    fn channel_pruned_model_equals_the_unpruned_one_with_those_channels_zeroed() {
        let m = tiny(2);
        let (p, kept) = prune_channels(&m, 0.5).unwrap();
        assert_eq!(p.config().backbone[1].out_channels, 8);
        assert_eq!(p.config().rpn_channels, 4);
        assert_eq!(p.config().roi_hidden, 16);
        assert!(parameter_count(&p) < parameter_count(&m) / 2);
        // zero the pruned filters (weights and biases) of the original
        let vars = m.var_store().variables();
        for (layer, k) in &kept {
            let w = &vars[&format!("{layer}.weight")];
            let n = w.size()[0];
            let drop: Vec<i64> = (0..n).filter(|c| !k.contains(c)).collect();
            tch::no_grad(|| {
                let _ = w.shallow_clone().index_fill_(0, &idx(&drop), 0.0);
                let _ =
                    vars[&format!("{layer}.bias")]
                        .shallow_clone()
                        .index_fill_(0, &idx(&drop), 0.0);
            });
        }
        let img = Tensor::randn([1, 3, 40, 56], (Kind::Float, Device::Cpu));
        let (a, b) = tch::no_grad(|| (m.backbone_rpn(&img), p.backbone_rpn(&img)));
        let feat = &kept["backbone.block2.conv0"];
        let fa = a.features.index_select(1, &idx(feat));
        let d = |x: &Tensor, y: &Tensor| (x - y).abs().max().double_value(&[]);
        assert!(d(&fa, &b.features) < 1e-5);
        assert!(d(&a.objectness, &b.objectness) < 1e-5);
        assert!(d(&a.deltas, &b.deltas) < 1e-5);
        let rois =
            Tensor::from_slice(&[2.0f32, 3.0, 30.0, 30.0, 10.0, 5.0, 50.0, 38.0]).reshape([2, 4]);
        let (la, da) = tch::no_grad(|| m.roi_head(&a.features, &rois, &[0, 0]));
        let (lb, db) = tch::no_grad(|| p.roi_head(&b.features, &rois, &[0, 0]));
        assert!(d(&la, &lb) < 1e-5 && d(&da, &db) < 1e-5);
    }

    #[test]
    fn layer_removal_keeps_shapes_consistent() {
        let m = tiny(3);
        let r = drop_blocks(&m, &[2]).unwrap();
        assert_eq!(r.config().backbone.len(), 2);
        assert_eq!(r.config().feature_channels(), 16);
        let layers = r.layers();
        // each backbone conv reads what the previous one writes; the RPN conv and fc1
        // read the new feature channels
        let mut ch = 3;
        for l in layers.iter().filter(|l| l.name.starts_with("backbone")) {
            assert_eq!(l.inputs, ch, "{}", l.name);
            ch = l.outputs;
        }
        let by = |n: &str| layers.iter().find(|l| l.name == n).unwrap().clone();
        assert_eq!(by("rpn.conv").inputs, 16);
        assert_eq!(by("roi_head.fc1").inputs, 16 * 49);
        // unchanged layers keep their weights
        let (a, b) = (m.var_store().variables(), r.var_store().variables());
        let same = |n: &str| (&a[n] - &b[n]).abs().max().double_value(&[]) == 0.0;
        assert!(same("backbone.block1.conv1.weight") && same("roi_head.fc2.weight"));
        // and it runs: dropping a stride-2 block changes the stride
        let s = drop_blocks(&m, &[1]).unwrap();
        assert_eq!(s.config().stride(), 2);
        let img = Tensor::randn([1, 3, 40, 56], (Kind::Float, Device::Cpu));
        let out = tch::no_grad(|| s.backbone_rpn(&img));
        assert_eq!(out.features.size(), vec![1, 12, 20, 28]);
        assert!(drop_blocks(&m, &[0, 1, 2]).is_err());
    }
}
