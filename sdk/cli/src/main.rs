//! `fbksd`: the command-line front of the SDK. Only argument parsing and
//! printing live here; the work is in `fbksd-manager`.

mod bench;
mod iqa;
mod page;
mod results;
mod run;

use clap::{Parser, Subcommand};

/// Develop and benchmark sampling and denoising techniques for Monte Carlo rendering.
#[derive(Parser)]
#[command(name = "fbksd", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run techniques on scenes at several sample budgets and write the results.
    Run(run::RunArgs),
    /// Compute or show the metric values of a results directory, or write its viewer.
    #[command(subcommand)]
    Results(results::ResultsCommand),
    /// Image quality metrics: list, compute one, benchmark.
    #[command(subcommand)]
    Iqa(iqa::IqaCommand),
    /// Measure the SDK itself.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Run(args) => run::run(args),
        Command::Results(command) => results::results(command),
        Command::Iqa(command) => iqa::iqa(command),
        Command::Bench(command) => bench::bench(command),
    }
}
