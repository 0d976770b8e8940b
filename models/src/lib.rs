//! Sign detectors and their variants.
#![deny(missing_docs)]

/// Smoke check that libtorch links (removed once the detector lands).
pub fn libtorch_version_check() -> i64 {
    tch::Tensor::from_slice(&[1i64, 2, 3]).sum(tch::Kind::Int64).int64_value(&[])
}

#[cfg(test)]
mod tests {
    #[test]
    fn libtorch_links_and_runs() {
        assert_eq!(super::libtorch_version_check(), 6);
    }
}
