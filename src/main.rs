//! The `lantern` binary: a thin shell over the library's command line.

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = lantern::cli::Cli::parse();
    match lantern::cli::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
