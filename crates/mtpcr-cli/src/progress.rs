//! Progress on stderr (indicatif). Bars draw only when stderr is a terminal; `--quiet` hides
//! them everywhere.

use indicatif::{ProgressBar, ProgressStyle};
use mtpcr_core::{Progress, Stage};
use std::ops::ControlFlow;
use std::time::Duration;

fn styled(bar: ProgressBar, template: &str, label: &str) -> ProgressBar {
    bar.set_style(
        ProgressStyle::with_template(template)
            .expect("the progress template is valid")
            .progress_chars("=> ")
            .tick_chars("|/-\\ "),
    );
    bar.set_prefix(label.to_string());
    bar.enable_steady_tick(Duration::from_millis(200));
    bar
}

/// A bar over the steps of one registration run: its generations, or the pairs screened
/// when four or more scans are given in no known order.
pub fn generation_bar(generations: usize, quiet: bool, label: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = styled(
        ProgressBar::new(generations as u64),
        "{prefix} {spinner} [{bar:25}] {pos}/{len} {msg} | {elapsed} ETA {eta}",
        label,
    );
    bar.set_message("preparing the clouds (downsampling, search structures)");
    bar
}

/// A bar over the runs of an evaluation.
pub fn run_bar(runs: usize, quiet: bool, label: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    styled(
        ProgressBar::new(runs as u64),
        "{prefix} {spinner} [{bar:25}] {pos}/{len} runs done | {msg} | {elapsed} ETA {eta}",
        label,
    )
}

/// The observer that moves `bar` after each generation (showing the best original costs,
/// the second half of the task slots) or each batch of pairs screened.
pub fn observe(bar: &ProgressBar) -> impl FnMut(&Progress) -> ControlFlow<()> + '_ {
    move |p: &Progress| {
        bar.set_length(p.generations as u64);
        bar.set_position(p.generation as u64);
        match p.stage {
            Stage::Generation => {
                let original = &p.best_costs[p.best_costs.len() / 2..];
                let shown: Vec<String> = original.iter().map(|c| format!("{c:.4}")).collect();
                bar.set_message(format!(
                    "generations, best original costs {}",
                    shown.join(" ")
                ));
            }
            Stage::PairScreening => bar.set_message("pairs screened for pose hypotheses"),
        }
        ControlFlow::Continue(())
    }
}

/// Registers with a generation bar on stderr; the bar is cleared when the run ends.
pub fn register_with_bar(
    clouds: &[mtpcr_core::PointCloud],
    config: &mtpcr_core::Config,
    quiet: bool,
    label: &str,
) -> mtpcr_core::Result<mtpcr_core::Registration> {
    let bar = generation_bar(config.restarts * config.generations, quiet, label);
    let mut observer = observe(&bar);
    let result = mtpcr_core::register(clouds, config, Some(&mut observer));
    bar.finish_and_clear();
    result
}
