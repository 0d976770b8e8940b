//! The `frugal` binary: see the library crate for the commands.
use std::process::ExitCode;

/// Keep freed memory in the process instead of handing it back to the kernel.
///
/// libtorch allocates and frees tensors of several megabytes on every training step;
/// glibc serves blocks that large with `mmap` and returns them on `free`, so each step
/// faulted the same pages in again (1.6 million page faults in 50 training steps,
/// ≈ 14 % of the CPU time). Raising the mmap and trim thresholds keeps those blocks in
/// the heap for reuse (83 thousand faults); the cost is a resident size that stays at
/// its peak. Record: `docs/experiments/2026-11-26-thirty-minute-default-run.md`.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)] // three mallopt calls
fn keep_freed_memory() {
    const MIB: libc::c_int = 1 << 20;
    // SAFETY: mallopt only sets allocator parameters; called before any other thread
    // exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 512 * MIB);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1024 * MIB);
        libc::mallopt(libc::M_TOP_PAD, 256 * MIB);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn keep_freed_memory() {}

fn main() -> ExitCode {
    keep_freed_memory();
    ExitCode::from(frugal::main_from(std::env::args_os()))
}
