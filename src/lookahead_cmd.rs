//! `nldf train lookahead`: a short-lookahead student from a trained one, so that a stream
//! renders each frame sooner.

use std::path::PathBuf;

use anyhow::Result;
use nldf_train::job::lookahead::LookaheadJob;
use nldf_train::trainers::lookahead::LookaheadConfig;

#[derive(clap::Args, Debug)]
pub struct LookaheadArgs {
    /// Dataset folder the student was trained on.
    #[arg(long)]
    pub data: PathBuf,
    /// Run folder holding the student.
    #[arg(long)]
    pub run: PathBuf,
    /// The student's folder inside RUN (one without audio attention, on nldf's features).
    #[arg(long, default_value = "student")]
    pub student: String,
    /// The new student's folder inside RUN.
    #[arg(long, default_value = "student_lookahead")]
    pub name: String,
    /// The most audio past a frame's instant its encoder may read, in milliseconds (the
    /// full encoder reads 152.5 at 50 Hz features; each feature frame less is 20 ms).
    #[arg(long, default_value_t = 100.0)]
    pub lookahead_ms: f64,
    /// Full-batch steps of the encoder's distillation.
    #[arg(long, default_value_t = LookaheadConfig::default().steps)]
    pub steps: usize,
}

/// Runs `nldf train lookahead`.
pub fn run(args: LookaheadArgs) -> Result<()> {
    let job = LookaheadJob {
        data: args.data,
        run: args.run.clone(),
        student: args.student,
        name: args.name.clone(),
        config: LookaheadConfig {
            lookahead_ms: args.lookahead_ms,
            steps: args.steps,
            ..LookaheadConfig::default()
        },
    };
    let bar = crate::progress::progress_bar(job.config.steps as u64, "lookahead");
    let report = job.run(&mut |step, loss| {
        bar.set_position(step as u64);
        if step % 50 == 0 {
            bar.set_message(format!("audio encoder, code loss {loss:.3e}"));
        }
    })?;
    bar.finish();
    println!(
        "short-lookahead student: {} feature frames past the centre, {:.1} ms of future \
         audio (the full encoder {:.1} ms); {} steps in {:.1} s",
        report.ahead,
        report.lookahead_ms,
        report.full_lookahead_ms,
        report.config.steps,
        report.train_s
    );
    println!("| frames | windows | code error before | after |");
    println!("|---|---|---|---|");
    for e in &report.code_error {
        println!(
            "| {} | {} | {:.4} | {:.4} |",
            e.frames, e.n, e.before, e.after
        );
    }
    println!(
        "code error: the mean squared difference from the full encoder's codes over the \
         variance of its codes of the training frames; wrote {}",
        args.run.join(&args.name).display()
    );
    Ok(())
}
