//! `frugal-pilot`: see the library documentation and `docs/guide/pilot.md`.
use clap::Parser;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

fn report(line: &str) {
    eprintln!("frugal-pilot: {line}");
}

fn main() -> std::process::ExitCode {
    let args = frugal_pilot::Args::parse();
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        if let Err(e) = signal_hook::flag::register(signal, Arc::clone(&stop)) {
            report(&format!("cannot watch signal {signal}: {e}"));
            return std::process::ExitCode::FAILURE;
        }
    }
    match frugal_pilot::run(&args, &stop, report) {
        Ok(summary) => {
            let failed = summary.input_error.clone();
            if let Some(e) = &failed {
                report(&format!("input ended: {e}"));
            }
            eprintln!("{}", summary.line());
            if failed.is_some() {
                std::process::ExitCode::FAILURE
            } else {
                std::process::ExitCode::SUCCESS
            }
        }
        Err(e) => {
            eprintln!("frugal-pilot: error: {:#}", anyhow::Error::from(e));
            std::process::ExitCode::FAILURE
        }
    }
}
