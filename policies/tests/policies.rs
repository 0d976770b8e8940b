//! Integration tests of frugal-policies: the solvers against independent
//! implementations, transition estimation, training, replay evaluation and bundles.

mod it;

use frugal_policies::Mdp;
use rand::{Rng, SeedableRng};

/// A random MDP shaped like frugal's: states = 3 confidence buckets × `variants`,
/// actions = variants, the next state's variant is the action taken.
fn random_mdp(rng: &mut rand_chacha::ChaCha8Rng, variants: usize) -> Mdp {
    let (s_n, a_n) = (3 * variants, variants);
    let mut p = vec![0.0; a_n * s_n * s_n];
    for a in 0..a_n {
        for s in 0..s_n {
            let w: Vec<f64> = (0..3).map(|_| rng.random_range(0.05..1.0)).collect();
            let total: f64 = w.iter().sum();
            for (bucket, wb) in w.iter().enumerate() {
                p[(a * s_n + s) * s_n + bucket * variants + a] = wb / total;
            }
        }
    }
    let r = (0..s_n * a_n)
        .map(|_| rng.random_range(0.0..10.0))
        .collect();
    Mdp::new(s_n, a_n, p, r).unwrap()
}

#[test]
fn value_iteration_agrees_with_policy_iteration_and_pymdptoolbox() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let cases: Vec<(Mdp, f64)> = (0..12)
        .map(|i| (random_mdp(&mut rng, 2 + i % 5), [0.5, 0.9, 0.95][i % 3]))
        .collect();
    let ours: Vec<_> = cases
        .iter()
        .map(|(m, g)| {
            let vi = m.value_iteration(*g, 1e-10).unwrap();
            let pi = m.policy_iteration(*g).unwrap();
            assert_eq!(vi.policy, pi.policy);
            for (a, b) in vi.values.iter().zip(&pi.values) {
                assert!((a - b).abs() < 1e-8, "VI {a} vs PI {b}");
            }
            vi
        })
        .collect();

    let input: Vec<serde_json::Value> = cases
        .iter()
        .map(|(m, g)| serde_json::json!({"states": m.states, "actions": m.actions, "p": m.p, "r": m.r, "gamma": g}))
        .collect();
    let theirs: Vec<serde_json::Value> = serde_json::from_value(it::fixture::python_peer(
        "mdptoolbox_check.py",
        &serde_json::json!(input),
    ))
    .unwrap();
    assert_eq!(theirs.len(), ours.len());
    for (mine, t) in ours.iter().zip(&theirs) {
        let pi_policy: Vec<usize> = serde_json::from_value(t["pi_policy"].clone()).unwrap();
        let vi_policy: Vec<usize> = serde_json::from_value(t["vi_policy"].clone()).unwrap();
        let pi_values: Vec<f64> = serde_json::from_value(t["pi_values"].clone()).unwrap();
        assert_eq!(mine.policy, pi_policy);
        assert_eq!(mine.policy, vi_policy);
        for (a, b) in mine.values.iter().zip(&pi_values) {
            assert!((a - b).abs() < 1e-6, "frugal {a} vs pymdptoolbox {b}");
        }
    }
}
