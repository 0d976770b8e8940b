//! A finite, discounted Markov Decision Process and its exact solvers.
//!
//! Transitions are dense, `P[a][s][s']`, rewards `R[s][a]` (the expected reward of
//! taking `a` in `s`). The layout is the one `pymdptoolbox` takes (`P` of shape
//! `(A, S, S)`, `R` of shape `(S, A)`), so the same matrices can be handed to it for an
//! independent check.

use serde::{Deserialize, Serialize};

/// Why an MDP is not well formed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MdpError {
    /// A matrix has the wrong number of entries.
    #[error("{what} has {got} entries, expected {expected}")]
    Shape {
        /// Which matrix.
        what: &'static str,
        /// Entries found.
        got: usize,
        /// Entries expected.
        expected: usize,
    },
    /// A row of `P` is not a probability distribution.
    #[error("P[{action}][{state}] sums to {sum}, not 1 (or has a negative or non-finite entry)")]
    NotStochastic {
        /// The action.
        action: usize,
        /// The state.
        state: usize,
        /// What the row sums to.
        sum: f64,
    },
    /// The discount is outside `[0, 1)`.
    #[error("discount {0} is outside [0, 1)")]
    Discount(f64),
    /// There are no states or no actions.
    #[error("an MDP needs at least one state and one action")]
    Empty,
}

/// A finite MDP with `S` states and `A` actions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Mdp {
    /// Number of states.
    pub states: usize,
    /// Number of actions.
    pub actions: usize,
    /// `p[(a * S + s) * S + s2]` = P(s2 | s, a).
    pub p: Vec<f64>,
    /// `r[s * A + a]` = expected reward of taking `a` in `s`.
    pub r: Vec<f64>,
}

/// A solved MDP: the greedy policy and the state values under it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Solution {
    /// `policy[s]` = the action to take in state `s`.
    pub policy: Vec<usize>,
    /// `values[s]` = expected discounted return from `s` following `policy`.
    pub values: Vec<f64>,
    /// Iterations (Bellman sweeps or policy improvements) until convergence.
    pub iterations: usize,
}

impl Mdp {
    /// Check shapes, stochasticity (rows sum to 1 within 1e-9) and finiteness.
    pub fn new(states: usize, actions: usize, p: Vec<f64>, r: Vec<f64>) -> Result<Mdp, MdpError> {
        if states == 0 || actions == 0 {
            return Err(MdpError::Empty);
        }
        let expected = actions * states * states;
        if p.len() != expected {
            return Err(MdpError::Shape {
                what: "P",
                got: p.len(),
                expected,
            });
        }
        if r.len() != states * actions {
            return Err(MdpError::Shape {
                what: "R",
                got: r.len(),
                expected: states * actions,
            });
        }
        for a in 0..actions {
            for s in 0..states {
                let row = &p[(a * states + s) * states..][..states];
                let sum: f64 = row.iter().sum();
                if row.iter().any(|v| !v.is_finite() || *v < 0.0) || (sum - 1.0).abs() > 1e-9 {
                    return Err(MdpError::NotStochastic {
                        action: a,
                        state: s,
                        sum,
                    });
                }
            }
        }
        if r.iter().any(|v| !v.is_finite()) {
            return Err(MdpError::Shape {
                what: "R (finite values)",
                got: 0,
                expected: r.len(),
            });
        }
        Ok(Mdp {
            states,
            actions,
            p,
            r,
        })
    }

    /// P(s2 | s, a).
    pub fn prob(&self, a: usize, s: usize, s2: usize) -> f64 {
        self.p[(a * self.states + s) * self.states + s2]
    }

    /// Q(s, a) = R(s, a) + γ Σ P(s'|s,a) V(s').
    fn q(&self, s: usize, a: usize, gamma: f64, v: &[f64]) -> f64 {
        let row = &self.p[(a * self.states + s) * self.states..][..self.states];
        self.r[s * self.actions + a] + gamma * row.iter().zip(v).map(|(p, v)| p * v).sum::<f64>()
    }

    /// The greedy action and its Q value in `s` (ties go to the lowest action index).
    fn greedy(&self, s: usize, gamma: f64, v: &[f64]) -> (usize, f64) {
        let mut best = (0, f64::NEG_INFINITY);
        for a in 0..self.actions {
            let q = self.q(s, a, gamma, v);
            if q > best.1 + 1e-12 {
                best = (a, q);
            }
        }
        best
    }

    fn check_discount(gamma: f64) -> Result<(), MdpError> {
        if (0.0..1.0).contains(&gamma) {
            Ok(())
        } else {
            Err(MdpError::Discount(gamma))
        }
    }

    /// Value iteration from V = 0 until the largest change in a sweep is below
    /// `tolerance · (1 − γ) / (2γ)`, which bounds the distance of the returned values
    /// from the optimal ones by `tolerance` (sup norm).
    pub fn value_iteration(&self, gamma: f64, tolerance: f64) -> Result<Solution, MdpError> {
        Self::check_discount(gamma)?;
        let stop = if gamma > 0.0 {
            tolerance * (1.0 - gamma) / (2.0 * gamma)
        } else {
            f64::INFINITY
        };
        let mut v = vec![0.0; self.states];
        let mut iterations = 0;
        loop {
            iterations += 1;
            let next: Vec<f64> = (0..self.states)
                .map(|s| self.greedy(s, gamma, &v).1)
                .collect();
            let delta = next
                .iter()
                .zip(&v)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            v = next;
            if delta < stop || iterations >= 1_000_000 {
                break;
            }
        }
        let policy: Vec<usize> = (0..self.states)
            .map(|s| self.greedy(s, gamma, &v).0)
            .collect();
        let values = self.evaluate(&policy, gamma)?;
        Ok(Solution {
            policy,
            values,
            iterations,
        })
    }

    /// Policy iteration with exact evaluation (a linear solve), from the policy that
    /// takes action 0 everywhere, until the policy is stable.
    pub fn policy_iteration(&self, gamma: f64) -> Result<Solution, MdpError> {
        Self::check_discount(gamma)?;
        let mut policy = vec![0usize; self.states];
        let mut iterations = 0;
        loop {
            iterations += 1;
            let v = self.evaluate(&policy, gamma)?;
            let mut changed = false;
            for (s, current) in policy.iter_mut().enumerate() {
                let (a, q) = self.greedy(s, gamma, &v);
                // Switch only on a real improvement, so ties cannot cycle.
                if a != *current && q > self.q(s, *current, gamma, &v) + 1e-12 {
                    *current = a;
                    changed = true;
                }
            }
            if !changed || iterations >= 10_000 {
                return Ok(Solution {
                    policy,
                    values: v,
                    iterations,
                });
            }
        }
    }

    /// The values of a fixed policy: solve (I − γ P_π) V = R_π by Gaussian elimination
    /// with partial pivoting (the matrix is strictly diagonally dominant for γ < 1).
    pub fn evaluate(&self, policy: &[usize], gamma: f64) -> Result<Vec<f64>, MdpError> {
        Self::check_discount(gamma)?;
        let n = self.states;
        if policy.len() != n || policy.iter().any(|&a| a >= self.actions) {
            return Err(MdpError::Shape {
                what: "policy",
                got: policy.len(),
                expected: n,
            });
        }
        // Augmented matrix [I − γ P_π | R_π], row-major, n × (n + 1).
        let mut m = vec![0.0; n * (n + 1)];
        for s in 0..n {
            let a = policy[s];
            for s2 in 0..n {
                m[s * (n + 1) + s2] = f64::from(u8::from(s == s2)) - gamma * self.prob(a, s, s2);
            }
            m[s * (n + 1) + n] = self.r[s * self.actions + a];
        }
        for col in 0..n {
            let pivot = (col..n)
                .max_by(|&i, &j| {
                    m[i * (n + 1) + col]
                        .abs()
                        .total_cmp(&m[j * (n + 1) + col].abs())
                })
                .unwrap_or(col);
            if pivot != col {
                for k in 0..=n {
                    m.swap(col * (n + 1) + k, pivot * (n + 1) + k);
                }
            }
            let d = m[col * (n + 1) + col];
            for row in 0..n {
                if row != col {
                    let f = m[row * (n + 1) + col] / d;
                    if f != 0.0 {
                        for k in col..=n {
                            m[row * (n + 1) + k] -= f * m[col * (n + 1) + k];
                        }
                    }
                }
            }
        }
        Ok((0..n)
            .map(|s| m[s * (n + 1) + n] / m[s * (n + 1) + s])
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// pymdptoolbox's `forest()` example (S = 3, A = 2, r1 = 4, r2 = 2, p = 0.1),
    /// whose solution at γ = 0.9 is known: policy (0, 0, 0),
    /// V = (26.244, 29.484, 33.484).
    fn forest() -> Mdp {
        let p = vec![
            0.1, 0.9, 0.0, 0.1, 0.0, 0.9, 0.1, 0.0, 0.9, // wait
            1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, // cut
        ];
        let r = vec![0.0, 0.0, 0.0, 1.0, 4.0, 2.0];
        Mdp::new(3, 2, p, r).unwrap()
    }

    #[test]
    fn value_and_policy_iteration_solve_the_forest_example() {
        let m = forest();
        let vi = m.value_iteration(0.9, 1e-9).unwrap();
        let pi = m.policy_iteration(0.9).unwrap();
        assert_eq!(vi.policy, vec![0, 0, 0]);
        assert_eq!(pi.policy, vec![0, 0, 0]);
        for (v, want) in pi.values.iter().zip([26.244, 29.484, 33.484]) {
            assert!((v - want).abs() < 1e-9, "{v} vs {want}");
        }
        for (a, b) in vi.values.iter().zip(&pi.values) {
            assert!((a - b).abs() < 1e-9);
        }
    }

    #[test]
    fn malformed_mdps_are_rejected() {
        assert_eq!(Mdp::new(0, 1, vec![], vec![]), Err(MdpError::Empty));
        assert!(matches!(
            Mdp::new(2, 1, vec![1.0; 3], vec![0.0; 2]),
            Err(MdpError::Shape { .. })
        ));
        assert!(matches!(
            Mdp::new(1, 1, vec![0.5], vec![0.0]),
            Err(MdpError::NotStochastic {
                action: 0,
                state: 0,
                ..
            })
        ));
        assert_eq!(
            forest().value_iteration(1.0, 1e-6),
            Err(MdpError::Discount(1.0))
        );
    }
}
