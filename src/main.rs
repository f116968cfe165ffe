//! The `rigidcells` command line: parse, call the library, report. See `rigidcells --help`
//! and the `cli` module.

mod cli;

fn main() -> std::process::ExitCode {
    cli::main()
}
