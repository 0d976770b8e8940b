//! End-to-end tests of the `frugal` binary on tiny configurations.
