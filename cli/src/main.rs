//! `dear`: the command-line client of `deard` (list, watch, dump, record, eval). The logic lives in the
//! `dear_cli` library (`cli/src/`); this file only parses, runs and maps the outcome to an exit
//! status.

#![forbid(unsafe_code)]

use dear_cli as cli;

use std::process::ExitCode;

use clap::Parser;

// tract allocates every intermediate tensor per inference; with glibc's malloc each one above
// the mmap threshold (a 32-channel 640×480 map is 39 MB) comes back as fresh zeroed pages.
// mimalloc reuses them: fusion network 215 -> 137 ms per VGA frame (criterion dear_chain).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    cli::init_logging();
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if cli::is_interrupt(&e) => {
            eprintln!("dear: {e:#}");
            ExitCode::from(130)
        }
        Err(e) => {
            eprintln!("dear: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
