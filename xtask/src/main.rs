//! frugal's set-up and top-level commands.
//!
//! * `cargo xtask setup` — fetch and assemble what the workspace needs, idempotently:
//!   a CPU-only libtorch for `tch` 0.26, the ONNX Runtime library for `ort`
//!   2.0.0-rc.15, a Python environment with the test peers (onnx, onnxruntime,
//!   OpenCV, pycocotools, pymdptoolbox, scikit-image, pymavlink), the `thumbv7em-none-eabihf`
//!   target and the system packages plotting and video need. Big downloads live in a cache
//!   outside the clone (`$FRUGAL_CACHE`, default `~/.cache/frugal`); the clone's
//!   git-ignored `.deps/` only links to it, so a fresh clone does not fetch again.
//! * `cargo xtask run [ARGS]` — set up, then run the main job (`frugal run`).
//! * `cargo xtask test` — set up, then every check: fmt, clippy, all tests, and the
//!   runtime crate built for a bare-metal target.
//!
//! Every failure ends with one line saying what went wrong and what to do.

use sha2::{Digest, Sha256};
use std::fmt::Write as _;
use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

/// A pinned download: the package spec given to pip and the file's SHA-256.
struct Wheel {
    spec: &'static str,
    file: &'static str,
    sha256: &'static str,
}

const TORCH: Wheel = Wheel {
    spec: "torch==2.13.0",
    file: "torch-2.13.0-cp311-cp311-manylinux_2_28_x86_64.whl",
    sha256: "60fcdcb2f3876e21146cb4524ef06397d727ca9ad5f020818547e25075fe3cb7",
};
const CUDART: Wheel = Wheel {
    spec: "nvidia-cuda-runtime==13.0.96",
    file: "nvidia_cuda_runtime-13.0.96-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl",
    sha256: "7f82250d7782aa23b6cfe765ecc7db554bd3c2870c43f3d1821f1d18aebf0548",
};
const CUPTI: Wheel = Wheel {
    spec: "nvidia-cuda-cupti==13.0.85",
    file: "nvidia_cuda_cupti-13.0.85-py3-none-manylinux_2_25_x86_64.whl",
    sha256: "4eb01c08e859bf924d222250d2e8f8b8ff6d3db4721288cf35d14252a4d933c8",
};
const ONNXRUNTIME: Wheel = Wheel {
    spec: "onnxruntime==1.31.1",
    file: "onnxruntime-1.31.1-cp311-cp311-manylinux_2_28_x86_64.whl",
    sha256: "5752bd508126ae7c49894d3b9d2e83f0c3d487319246d04c444b393308d7ad7f",
};

const LIBTORCH_DIR: &str = "libtorch-2.13.0-cpu";
const LIBTORCH_CUDA_DIR: &str = "libtorch-2.13.0-cuda";

/// Which libtorch `.deps/libtorch` points at.
#[derive(Clone, Copy, PartialEq)]
enum Torch {
    /// The CPU-only libtorch (the default, tested path).
    Cpu,
    /// A CUDA libtorch (`setup --cuda`).
    Cuda,
    /// Whatever was set up last (CPU on a fresh machine).
    Keep,
}
const ORT_DIR: &str = "onnxruntime-1.31.1";
const ORT_LIB: &str = "libonnxruntime.so.1.31.1";
const BARE_METAL_TARGET: &str = "thumbv7em-none-eabihf";
/// Debian packages: fontconfig and a TrueType font for plot labels, and FFmpeg for
/// video import and the pilot.
const APT_PACKAGES: &[&str] = &["libfontconfig1-dev", "fonts-dejavu-core", "ffmpeg"];

type Result<T> = std::result::Result<T, String>;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let outcome = match args.first().map(String::as_str) {
        Some("setup") => match args.get(1).map(String::as_str) {
            None => setup(Torch::Cpu).map(|_| ()),
            Some("--cuda") => setup(Torch::Cuda).map(|_| ()),
            Some(other) => Err(format!("unknown setup option `{other}` (allowed: --cuda)")),
        },
        Some("run") => setup(Torch::Keep).and_then(|_| main_job(&args[1..])),
        Some("test") => setup(Torch::Keep).and_then(|_| test_all()),
        _ => {
            eprintln!(
                "usage: cargo xtask <setup [--cuda]|run [ARGS]|test>\n\
                 \n  setup  fetch libtorch, ONNX Runtime, Python test peers and the bare-metal target\
                 \n         (--cuda: a CUDA libtorch instead of the CPU one, for `frugal train --device cuda`)\
                 \n  run    set up, then run the whole pipeline on the built-in synthetic data\
                 \n  test   set up, then run every check (fmt, clippy, tests, no_std build)"
            );
            return ExitCode::from(2);
        }
    };
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("xtask: {message}");
            ExitCode::FAILURE
        }
    }
}

/// The clone `cargo xtask` was run in: `cargo run` tells the process where its
/// manifest is, so a binary built in another clone sharing the target folder still
/// works on this one; the path it was built from otherwise.
fn workspace_root() -> PathBuf {
    let here = std::env::var_os("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")));
    here.parent()
        .map_or_else(|| here.clone(), Path::to_path_buf)
}

fn cache_dir() -> Result<PathBuf> {
    if let Some(dir) = std::env::var_os("FRUGAL_CACHE") {
        return Ok(PathBuf::from(dir));
    }
    if let Some(dir) = std::env::var_os("XDG_CACHE_HOME") {
        return Ok(PathBuf::from(dir).join("frugal"));
    }
    std::env::var_os("HOME")
        .map(|home| PathBuf::from(home).join(".cache").join("frugal"))
        .ok_or_else(|| {
            "neither FRUGAL_CACHE nor HOME is set: set FRUGAL_CACHE to a writable folder".into()
        })
}

/// Run a command, failing with `what` and its exit status.
fn run(cmd: &mut Command, what: &str) -> Result<()> {
    let status = cmd
        .status()
        .map_err(|e| format!("{what}: could not start {:?}: {e}", cmd.get_program()))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("{what} failed ({status})"))
    }
}

fn cargo() -> Command {
    let mut cmd = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    cmd.current_dir(workspace_root());
    cmd
}

fn sha256_of(path: &Path) -> Result<String> {
    let mut file =
        fs::File::open(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = file
            .read(&mut buf)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    let mut hex = String::with_capacity(64);
    for byte in hasher.finalize() {
        let _ = write!(hex, "{byte:02x}");
    }
    Ok(hex)
}

fn check_python() -> Result<()> {
    let ok = Command::new("python3")
        .args(["-m", "pip", "--version"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    if ok {
        Ok(())
    } else {
        Err("python3 with pip is needed to fetch libtorch and ONNX Runtime: install it (apt-get install python3-pip) and run again".into())
    }
}

/// Download a pinned wheel into the cache unless a file with the right hash is there.
fn fetch_wheel(wheels: &Path, wheel: &Wheel) -> Result<PathBuf> {
    let path = wheels.join(wheel.file);
    if path.exists() && sha256_of(&path)? == wheel.sha256 {
        return Ok(path);
    }
    eprintln!(
        "xtask: downloading {} into {}",
        wheel.spec,
        wheels.display()
    );
    fs::create_dir_all(wheels).map_err(|e| format!("cannot create {}: {e}", wheels.display()))?;
    run(
        Command::new("python3")
            .args([
                "-m",
                "pip",
                "download",
                "--no-deps",
                "--only-binary=:all:",
                "--quiet",
                "-d",
            ])
            .arg(wheels)
            .arg(wheel.spec),
        &format!(
            "downloading {} (check the network and pip's index settings, then run again)",
            wheel.spec
        ),
    )?;
    if !path.exists() {
        return Err(format!(
            "pip did not produce {} for {}: this set-up is pinned to CPython 3.11 on x86-64 Linux",
            wheel.file, wheel.spec
        ));
    }
    let got = sha256_of(&path)?;
    if got != wheel.sha256 {
        let _ = fs::remove_file(&path);
        return Err(format!(
            "{} has SHA-256 {got}, expected {}: the download was removed, run again",
            wheel.file, wheel.sha256
        ));
    }
    Ok(path)
}

/// Extract members of a wheel (a zip) whose names start with one of `prefixes` into
/// `dest`, dropping `strip` from the front of each name.
fn extract(wheel: &Path, prefixes: &[&str], strip: &str, dest: &Path) -> Result<()> {
    const SCRIPT: &str = r#"
import sys, zipfile, os, shutil
wheel, strip, dest = sys.argv[1], sys.argv[2], sys.argv[3]
prefixes = sys.argv[4:]
with zipfile.ZipFile(wheel) as z:
    for info in z.infolist():
        name = info.filename
        if info.is_dir() or not any(name.startswith(p) for p in prefixes):
            continue
        out = os.path.join(dest, name[len(strip):])
        os.makedirs(os.path.dirname(out), exist_ok=True)
        with z.open(info) as src, open(out, "wb") as dst:
            shutil.copyfileobj(src, dst)
"#;
    run(
        Command::new("python3")
            .args(["-c", SCRIPT])
            .arg(wheel)
            .arg(strip)
            .arg(dest)
            .args(prefixes),
        &format!("unpacking {}", wheel.display()),
    )
}

/// Build a folder in the cache atomically: `fill` writes into a temporary sibling,
/// which is renamed into place only when complete.
fn build_dir(dir: &Path, fill: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    if dir.join(".complete").exists() {
        return Ok(());
    }
    let tmp = dir.with_extension("partial");
    let _ = fs::remove_dir_all(&tmp);
    fs::create_dir_all(&tmp).map_err(|e| format!("cannot create {}: {e}", tmp.display()))?;
    fill(&tmp)?;
    fs::write(tmp.join(".complete"), b"")
        .map_err(|e| format!("cannot write in {}: {e}", tmp.display()))?;
    let _ = fs::remove_dir_all(dir);
    fs::rename(&tmp, dir).map_err(|e| format!("cannot move {} into place: {e}", dir.display()))
}

fn assemble_libtorch(cache: &Path) -> Result<PathBuf> {
    let dir = cache.join(LIBTORCH_DIR);
    let wheels = cache.join("wheels");
    build_dir(&dir, |tmp| {
        let torch = fetch_wheel(&wheels, &TORCH)?;
        let cudart = fetch_wheel(&wheels, &CUDART)?;
        let cupti = fetch_wheel(&wheels, &CUPTI)?;
        eprintln!("xtask: assembling a CPU-only libtorch in {}", dir.display());
        extract(&torch, &["torch/include/"], "torch/", tmp)?;
        let libs: Vec<String> = ["libtorch_cpu.so", "libc10.so", "libgomp.so.1", "libshm.so"]
            .iter()
            .map(|l| format!("torch/lib/{l}"))
            .collect();
        let libs: Vec<&str> = libs.iter().map(String::as_str).collect();
        extract(&torch, &libs, "torch/", tmp)?;
        extract(
            &cudart,
            &["nvidia/cu13/lib/libcudart.so.13"],
            "nvidia/cu13/",
            tmp,
        )?;
        extract(
            &cupti,
            &["nvidia/cu13/lib/libcupti.so.13"],
            "nvidia/cu13/",
            tmp,
        )?;
        // torch-sys always links `-ltorch`; the wheel's libtorch.so pulls in the CUDA
        // libraries, so an empty library of that name stands in for it.
        let empty_c = tmp.join("empty.c");
        fs::write(&empty_c, b"").map_err(|e| format!("cannot write {}: {e}", empty_c.display()))?;
        run(
            Command::new("cc")
                .args(["-shared", "-fPIC", "-o"])
                .arg(tmp.join("lib/libtorch.so"))
                .arg(&empty_c),
            "building the empty libtorch.so stand-in (is a C compiler installed? apt-get install gcc)",
        )?;
        let _ = fs::remove_file(&empty_c);
        fs::write(tmp.join("build-version"), b"2.13.0\n")
            .map_err(|e| format!("cannot write build-version: {e}"))
    })?;
    Ok(dir)
}

/// A CUDA libtorch: the same pinned torch wheel, with every library kept, plus the
/// CUDA wheels it depends on. Their exact versions come from the torch wheel's own
/// metadata; pip resolves them (several GB, not hash-pinned here, and not exercised by
/// CI, whose machines have no GPU).
fn assemble_libtorch_cuda(cache: &Path) -> Result<PathBuf> {
    let dir = cache.join(LIBTORCH_CUDA_DIR);
    let wheels = cache.join("wheels");
    build_dir(&dir, |tmp| {
        let torch = fetch_wheel(&wheels, &TORCH)?;
        let site = tmp.join("site");
        eprintln!(
            "xtask: installing torch 2.13.0 with its CUDA libraries into {}",
            site.display()
        );
        run(
            Command::new("python3")
                .args([
                    "-m",
                    "pip",
                    "install",
                    "--quiet",
                    "--no-compile",
                    "--only-binary=:all:",
                    "--target",
                ])
                .arg(&site)
                .arg(&torch),
            "installing torch 2.13.0 and its CUDA wheels (check the network and pip's index settings, then run again)",
        )?;
        let lib = tmp.join("lib");
        fs::create_dir_all(&lib).map_err(|e| format!("cannot create {}: {e}", lib.display()))?;
        let rename = |from: &Path, to: &Path| {
            fs::rename(from, to)
                .map_err(|e| format!("cannot move {} to {}: {e}", from.display(), to.display()))
        };
        rename(&site.join("torch/include"), &tmp.join("include"))?;
        // torch's own libraries, then every CUDA library of the nvidia wheels
        let mut lib_dirs = vec![site.join("torch/lib")];
        let nvidia = site.join("nvidia");
        for entry in fs::read_dir(&nvidia)
            .map_err(|e| {
                format!(
                    "{}: {e} (did pip install the CUDA wheels?)",
                    nvidia.display()
                )
            })?
            .flatten()
        {
            for sub in [entry.path().join("lib"), entry.path().join("cu13/lib")] {
                if sub.is_dir() {
                    lib_dirs.push(sub);
                }
            }
        }
        for d in lib_dirs {
            for f in fs::read_dir(&d)
                .map_err(|e| format!("{}: {e}", d.display()))?
                .flatten()
            {
                rename(&f.path(), &lib.join(f.file_name()))?;
            }
        }
        fs::remove_dir_all(&site).map_err(|e| format!("cannot remove {}: {e}", site.display()))?;
        fs::write(tmp.join("build-version"), b"2.13.0\n")
            .map_err(|e| format!("cannot write build-version: {e}"))
    })?;
    Ok(dir)
}

fn assemble_onnxruntime(cache: &Path) -> Result<PathBuf> {
    let dir = cache.join(ORT_DIR);
    let wheels = cache.join("wheels");
    build_dir(&dir, |tmp| {
        let wheel = fetch_wheel(&wheels, &ONNXRUNTIME)?;
        extract(
            &wheel,
            &[&format!("onnxruntime/capi/{ORT_LIB}")],
            "onnxruntime/capi/",
            tmp,
        )?;
        symlink(Path::new(ORT_LIB), &tmp.join("libonnxruntime.so"))
    })?;
    Ok(dir)
}

/// The Python test peers, in a virtual environment keyed by the requirements' hash.
fn python_env(cache: &Path) -> Result<PathBuf> {
    let reqs = workspace_root()
        .join("tests")
        .join("python-requirements.txt");
    let key = sha256_of(&reqs)?;
    let dir = cache.join(format!("venv-{}", &key[..12]));
    if dir.join(".complete").exists() {
        return Ok(dir);
    }
    eprintln!(
        "xtask: installing the Python test peers into {}",
        dir.display()
    );
    let _ = fs::remove_dir_all(&dir);
    run(
        Command::new("python3").args(["-m", "venv"]).arg(&dir),
        "creating a Python virtual environment (apt-get install python3-venv, then run again)",
    )?;
    run(
        Command::new(dir.join("bin/python"))
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--disable-pip-version-check",
                "-r",
            ])
            .arg(&reqs),
        "installing the Python test peers (check the network and pip's index settings, then run again)",
    )?;
    fs::write(dir.join(".complete"), b"")
        .map_err(|e| format!("cannot write in {}: {e}", dir.display()))?;
    Ok(dir)
}

fn bare_metal_target() -> Result<()> {
    let installed = Command::new("rustup")
        .args(["target", "list", "--installed"])
        .output()
        .map_err(|e| format!("rustup is needed to add {BARE_METAL_TARGET}: {e}"))?;
    if String::from_utf8_lossy(&installed.stdout)
        .lines()
        .any(|l| l.trim() == BARE_METAL_TARGET)
    {
        return Ok(());
    }
    run(
        Command::new("rustup").args(["target", "add", BARE_METAL_TARGET]),
        &format!("rustup target add {BARE_METAL_TARGET}"),
    )
}

fn system_packages() -> Result<()> {
    let missing: Vec<&str> = APT_PACKAGES
        .iter()
        .copied()
        .filter(|p| {
            !Command::new("dpkg")
                .args(["-s", p])
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .status()
                .map(|s| s.success())
                .unwrap_or(false)
        })
        .collect();
    if missing.is_empty() {
        return Ok(());
    }
    eprintln!("xtask: installing {}", missing.join(" "));
    run(
        Command::new("apt-get").arg("update").arg("-qq"),
        "apt-get update",
    )?;
    run(
        Command::new("apt-get")
            .args(["install", "-y", "-qq", "--no-install-recommends"])
            .args(&missing)
            .env("DEBIAN_FRONTEND", "noninteractive"),
        &format!(
            "apt-get install {} (run as root, or install them by hand)",
            missing.join(" ")
        ),
    )
}

fn symlink(target: &Path, link: &Path) -> Result<()> {
    if fs::read_link(link).ok().as_deref() == Some(target) {
        return Ok(());
    }
    let _ = fs::remove_file(link);
    let _ = fs::remove_dir_all(link);
    std::os::unix::fs::symlink(target, link).map_err(|e| {
        format!(
            "cannot link {} -> {}: {e}",
            link.display(),
            target.display()
        )
    })
}

/// Everything the workspace needs; returns the `.deps` folder.
fn setup(torch: Torch) -> Result<PathBuf> {
    check_python()?;
    system_packages()?;
    let cache = cache_dir()?;
    fs::create_dir_all(&cache).map_err(|e| format!("cannot create {}: {e}", cache.display()))?;
    let link = workspace_root().join(".deps/libtorch");
    let keep_cuda = torch == Torch::Keep
        && fs::read_link(&link).is_ok_and(|t| t.ends_with(LIBTORCH_CUDA_DIR))
        && cache.join(LIBTORCH_CUDA_DIR).join(".complete").exists();
    let libtorch = if torch == Torch::Cuda || keep_cuda {
        assemble_libtorch_cuda(&cache)?
    } else {
        assemble_libtorch(&cache)?
    };
    let ort = assemble_onnxruntime(&cache)?;
    let venv = python_env(&cache)?;
    bare_metal_target()?;
    let deps = workspace_root().join(".deps");
    fs::create_dir_all(&deps).map_err(|e| format!("cannot create {}: {e}", deps.display()))?;
    symlink(&libtorch, &deps.join("libtorch"))?;
    symlink(&ort, &deps.join("onnxruntime"))?;
    symlink(&venv, &deps.join("python"))?;
    Ok(deps)
}

fn main_job(args: &[String]) -> Result<()> {
    run(
        cargo()
            .args(["run", "--release", "--quiet", "-p", "frugal", "--", "run"])
            .args(args),
        "frugal run",
    )
}

fn test_all() -> Result<()> {
    run(
        cargo().args(["fmt", "--all", "--check"]),
        "cargo fmt --check (run `cargo fmt --all`)",
    )?;
    run(
        cargo().args([
            "clippy",
            "--workspace",
            "--all-targets",
            "--quiet",
            "--",
            "-D",
            "warnings",
        ]),
        "cargo clippy",
    )?;
    run(
        cargo().args([
            "build",
            "--quiet",
            "-p",
            "frugal-runtime",
            "--no-default-features",
            "--target",
            BARE_METAL_TARGET,
        ]),
        "building frugal-runtime for the bare-metal target (no_std, no alloc)",
    )?;
    run(cargo().args(["test", "--workspace"]), "cargo test")
}
