//! SGD with momentum and AdamW over a [`tch::nn::VarStore`], with their state kept in
//! named tensors so a checkpoint can save and restore it exactly (tch's own optimizers
//! do not expose their state).
use crate::ModelError;
use crate::config::{OptimizerKind, TrainConfig};
use std::collections::BTreeMap;
use std::path::Path;
use tch::{Kind, Tensor, nn};

const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const EPS: f64 = 1e-8;
const MOMENTUM: f64 = 0.9;
/// Gradients are rescaled when their global L2 norm exceeds this.
const CLIP_NORM: f64 = 10.0;

/// The optimizer and its per-variable state.
pub struct Optimizer {
    kind: OptimizerKind,
    weight_decay: f64,
    vars: BTreeMap<String, Tensor>,
    /// first moment (AdamW) or momentum buffer (SGD), per variable
    m: BTreeMap<String, Tensor>,
    /// second moment (AdamW only)
    v: BTreeMap<String, Tensor>,
    /// Steps taken.
    pub step: u64,
}

impl Optimizer {
    /// A fresh optimizer over every variable of `vs`.
    pub fn new(vs: &nn::VarStore, tc: &TrainConfig) -> Self {
        let vars: BTreeMap<String, Tensor> = vs.variables().into_iter().collect();
        let zeros = |t: &Tensor| t.zeros_like().detach();
        let m = vars.iter().map(|(k, t)| (k.clone(), zeros(t))).collect();
        let v = vars.iter().map(|(k, t)| (k.clone(), zeros(t))).collect();
        Self {
            kind: tc.optimizer,
            weight_decay: tc.weight_decay,
            vars,
            m,
            v,
            step: 0,
        }
    }

    /// Zero every gradient.
    pub fn zero_grad(&mut self) {
        for t in self.vars.values_mut() {
            t.zero_grad();
        }
    }

    /// One update with learning rate `lr` (gradients clipped to a global norm of 10).
    pub fn step(&mut self, lr: f64) {
        self.step += 1;
        tch::no_grad(|| {
            let norms: Vec<Tensor> = self
                .vars
                .values()
                .map(|t| t.grad())
                .filter(|g| g.defined())
                .map(|g| g.pow_tensor_scalar(2).sum(Kind::Float))
                .collect();
            let total = if norms.is_empty() {
                0.0
            } else {
                Tensor::stack(&norms, 0)
                    .sum(Kind::Float)
                    .sqrt()
                    .double_value(&[])
            };
            let scale = if total > CLIP_NORM {
                CLIP_NORM / (total + 1e-6)
            } else {
                1.0
            };
            let t = self.step as i32;
            for (name, p) in self.vars.iter_mut() {
                let g = p.grad();
                if !g.defined() {
                    continue;
                }
                let g = &g * scale;
                let decay = if p.dim() > 1 { self.weight_decay } else { 0.0 };
                let m = self.m.get_mut(name).expect("state for every variable");
                match self.kind {
                    OptimizerKind::AdamW => {
                        let v = self.v.get_mut(name).expect("state for every variable");
                        let _ = m.g_mul_scalar_(BETA1).g_add_(&(&g * (1.0 - BETA1)));
                        let _ = v.g_mul_scalar_(BETA2).g_add_(&(&g * &g * (1.0 - BETA2)));
                        let mhat = &*m / (1.0 - BETA1.powi(t));
                        let vhat = &*v / (1.0 - BETA2.powi(t));
                        let upd = mhat / (vhat.sqrt() + EPS) + &*p * decay;
                        let _ = p.g_sub_(&(upd * lr));
                    }
                    OptimizerKind::Sgd => {
                        let g = g + &*p * decay;
                        let _ = m.g_mul_scalar_(MOMENTUM).g_add_(&g);
                        let _ = p.g_sub_(&(&*m * lr));
                    }
                }
            }
        });
    }

    /// Save the state (`m.<var>`, `v.<var>` and the step) as safetensors.
    pub fn save(&self, path: &Path) -> Result<(), ModelError> {
        let mut named: Vec<(String, Tensor)> = Vec::new();
        for (k, t) in &self.m {
            named.push((format!("m.{k}"), t.shallow_clone()));
        }
        for (k, t) in &self.v {
            named.push((format!("v.{k}"), t.shallow_clone()));
        }
        named.push(("step".into(), Tensor::from_slice(&[self.step as i64])));
        Tensor::write_safetensors(&named, path).map_err(|e| ModelError::Torch {
            file: path.display().to_string(),
            msg: e.to_string(),
        })
    }

    /// Restore the state saved by [`Optimizer::save`]; every buffer must be present
    /// with the right shape.
    pub fn load(&mut self, path: &Path) -> Result<(), ModelError> {
        let file = path.display().to_string();
        let bad = |msg: String| ModelError::Checkpoint {
            file: file.clone(),
            msg,
        };
        let named: BTreeMap<String, Tensor> = Tensor::read_safetensors(path)
            .map_err(|e| bad(format!("not a readable safetensors file ({e})")))?
            .into_iter()
            .collect();
        for (prefix, state) in [("m", &mut self.m), ("v", &mut self.v)] {
            for (k, t) in state.iter_mut() {
                let src = named
                    .get(&format!("{prefix}.{k}"))
                    .ok_or_else(|| bad(format!("optimizer buffer `{prefix}.{k}` is missing")))?;
                if src.size() != t.size() {
                    return Err(bad(format!(
                        "optimizer buffer `{prefix}.{k}` has shape {:?}, expected {:?}",
                        src.size(),
                        t.size()
                    )));
                }
                tch::no_grad(|| t.copy_(src));
            }
        }
        let step = named
            .get("step")
            .ok_or_else(|| bad("optimizer step is missing".into()))?;
        self.step = step.int64_value(&[0]) as u64;
        Ok(())
    }
}

/// Learning rate at `step` of `total`: linear warm-up from `lr/10`, then cosine decay
/// to `lr · final_lr_fraction`.
pub fn learning_rate(tc: &TrainConfig, step: usize, total: usize) -> f64 {
    if step < tc.warmup_steps {
        let f = step as f64 / tc.warmup_steps as f64;
        return tc.lr * (0.1 + 0.9 * f);
    }
    let span = total.saturating_sub(tc.warmup_steps).max(1) as f64;
    let prog = ((step - tc.warmup_steps) as f64 / span).min(1.0);
    let lo = tc.lr * tc.final_lr_fraction;
    lo + (tc.lr - lo) * 0.5 * (1.0 + (std::f64::consts::PI * prog).cos())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::Device;

    #[test]
    fn both_optimizers_minimise_a_quadratic_and_state_round_trips() {
        for kind in [OptimizerKind::AdamW, OptimizerKind::Sgd] {
            let vs = nn::VarStore::new(Device::Cpu);
            let x = vs.root().var("x", &[3], nn::Init::Const(5.0));
            let tc = TrainConfig {
                optimizer: kind,
                weight_decay: 0.0,
                ..Default::default()
            };
            let mut opt = Optimizer::new(&vs, &tc);
            for _ in 0..300 {
                opt.zero_grad();
                (&x * &x).sum(Kind::Float).backward();
                opt.step(0.05);
            }
            assert!(x.abs().max().double_value(&[]) < 0.5, "{kind:?}: {x}");
            let dir = tempfile::tempdir().unwrap();
            let p = dir.path().join("o.safetensors");
            opt.save(&p).unwrap();
            let mut other = Optimizer::new(&vs, &tc);
            other.load(&p).unwrap();
            assert_eq!(other.step, 300);
            assert!(other.m["x"].allclose(&opt.m["x"], 0.0, 0.0, false));
        }
    }

    #[test]
    fn schedule_warms_up_then_decays() {
        let tc = TrainConfig {
            lr: 1.0,
            warmup_steps: 10,
            final_lr_fraction: 0.1,
            ..Default::default()
        };
        assert!((learning_rate(&tc, 0, 100) - 0.1).abs() < 1e-12);
        assert!((learning_rate(&tc, 10, 100) - 1.0).abs() < 1e-12);
        assert!((learning_rate(&tc, 100, 100) - 0.1).abs() < 1e-12);
        assert!(learning_rate(&tc, 50, 100) < 1.0);
    }
}
