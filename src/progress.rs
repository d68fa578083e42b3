//! Progress bars shared by the long-running commands.

use indicatif::{ProgressBar, ProgressStyle};

/// A bar of `len` steps labelled `what`, with rate and time left.
pub fn progress_bar(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    let style = ProgressStyle::with_template(
        "{msg} [{bar:40.cyan/blue}] {pos}/{len} ({per_sec}, eta {eta})",
    )
    .unwrap_or_else(|_| ProgressStyle::default_bar())
    .progress_chars("=> ");
    bar.set_style(style);
    bar.set_message(what.to_string());
    bar
}

/// Shows a training job's events: a progress bar per training stage and per counted piece
/// of work, stage headings, notes on stderr and the files each stage wrote.
#[derive(Default)]
pub struct EventPrinter {
    bar: Option<ProgressBar>,
    last_val: String,
}

impl EventPrinter {
    /// Shows one event.
    pub fn show(&mut self, event: &nldf_train::job::JobEvent) {
        use nldf_train::job::JobEvent;
        match event {
            JobEvent::Stage(line) => println!("== {line}"),
            JobEvent::Note(line) => eprintln!("{line}"),
            JobEvent::TrainingStarts { stage, step, iters } => {
                arm_ctrl_c();
                let bar = progress_bar(*iters as u64, stage);
                bar.set_position(*step as u64);
                self.last_val.clear();
                self.bar = Some(bar);
            }
            JobEvent::Training { stage, event } => self.show_training(stage, event),
            JobEvent::TrainingEnds {
                stage,
                step,
                interrupted,
                scores,
            } => self.training_ends(stage, *step, *interrupted, scores.as_ref()),
            JobEvent::Progress { what, done, total } => {
                let bar = self
                    .bar
                    .get_or_insert_with(|| progress_bar(*total as u64, what));
                bar.set_length(*total as u64);
                bar.set_position(*done as u64);
                if done >= total {
                    bar.finish_and_clear();
                    self.bar = None;
                }
            }
            JobEvent::Wrote { dir, files } => {
                if let Some(bar) = self.bar.take() {
                    bar.finish_and_clear();
                }
                println!("wrote to {}:", dir.display());
                for f in files {
                    println!("  {}", f.display());
                }
            }
        }
    }

    /// Shows a training stage's step or validation on its bar.
    fn show_training(&mut self, stage: &str, event: &nldf_train::trainers::run_loop::Event) {
        use nldf_train::trainers::run_loop::Event;
        let Some(bar) = &self.bar else { return };
        match event {
            Event::Step {
                step,
                loss,
                psnr,
                rays_per_s,
            } => {
                bar.set_position(*step as u64);
                bar.set_message(format!(
                    "{stage} loss {loss:.2e} psnr {psnr:.2} dB {rays_per_s:.0} rays/s{}",
                    self.last_val
                ));
            }
            Event::Validation { step, scores } => {
                let head = scores
                    .head_psnr
                    .map_or(String::new(), |h| format!("head {h:.2} dB, "));
                self.last_val = format!(" | val {head}{:.2} dB", scores.psnr);
                bar.println(format!(
                    "step {step}: validation {head}whole frame {:.2} dB, SSIM {:.4}{}",
                    scores.psnr,
                    scores.ssim,
                    scores
                        .mouth_psnr
                        .map_or(String::new(), |m| format!(", mouth {m:.2} dB"))
                ));
            }
            Event::Checkpoint { .. } => {}
        }
    }

    /// Closes a training stage's bar, says how it ended and prints its last scores.
    fn training_ends(
        &mut self,
        stage: &str,
        step: usize,
        interrupted: bool,
        scores: Option<&nldf_train::trainers::scores::Scores>,
    ) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
        if interrupted {
            println!("interrupted at step {step}; checkpoint written, continue with --resume");
        }
        if let Some(s) = scores {
            println!(
                "{}",
                serde_json::json!({"stage": stage, "step": step, "val": s})
            );
        }
    }
}

/// The flag that stops training at the next step with a checkpoint. Ctrl-C sets it once a
/// training stage has started ([`arm_ctrl_c`]); before that, Ctrl-C ends the process as usual.
pub fn stop_flag() -> std::sync::Arc<std::sync::atomic::AtomicBool> {
    use std::sync::atomic::AtomicBool;
    use std::sync::{Arc, OnceLock};
    static STOP: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    STOP.get_or_init(|| Arc::new(AtomicBool::new(false)))
        .clone()
}

/// Makes Ctrl-C set [`stop_flag`] (once per process).
pub fn arm_ctrl_c() {
    use std::sync::OnceLock;
    use std::sync::atomic::Ordering;
    static ARMED: OnceLock<()> = OnceLock::new();
    ARMED.get_or_init(|| {
        let flag = stop_flag();
        if let Err(e) = ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed)) {
            eprintln!("Ctrl-C will end training without a checkpoint: {e}");
        }
    });
}
