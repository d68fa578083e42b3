//! `nldf train`'s flags: which job each asks for.

use clap::Parser;

use super::*;

#[derive(Parser)]
struct Cli {
    #[command(flatten)]
    student: StudentArgs,
}

fn source(extra: &[&str]) -> StudentSource {
    let mut argv = vec!["nldf", "--data", "d", "--run", "r"];
    argv.extend_from_slice(extra);
    Cli::try_parse_from(argv)
        .unwrap()
        .student
        .job()
        .unwrap()
        .source
}

/// `nldf train student` with no shape flags trains the recipe's student, the one
/// `nldf train --data` trains; a preset or a switch asks for the plain settings.
#[test]
fn a_student_without_flags_is_the_recipes() {
    let defaults = nldf_pipeline::demo::DemoJob::defaults("r".into());
    let recipe = nldf_train::job::recipe::student_recipe(
        &defaults.student,
        &defaults.teacher,
        true,
        defaults.pseudo,
        defaults.student_iters,
    )
    .unwrap();
    match source(&[]) {
        StudentSource::Config(cfg) => {
            assert_eq!(
                serde_json::to_value(&*cfg).unwrap(),
                serde_json::to_value(&recipe).unwrap()
            );
            assert_eq!(
                cfg.model,
                nldf_train::networks::student::StudentConfig::realtime()
            );
            assert_eq!(cfg.train.pseudo_frames, 600);
        }
        _ => panic!("not the recipe"),
    }
    assert_eq!(
        (recipe.train.lr, recipe.train.iters),
        (
            nldf_train::job::recipe::DEMO_GRID_STUDENT_LR,
            nldf_train::job::recipe::DEMO_GRID_STUDENT_ITERS
        ),
        "without a teacher the recipe's student is the default (grid) teacher's"
    );
    for flags in [
        &["--depth", "88"][..],
        &["--no-pool"],
        &["--pseudo-frames", "10"],
    ] {
        assert!(
            matches!(source(flags), StudentSource::Settings { .. }),
            "{flags:?}"
        );
    }
}

/// Under a trained grid teacher, `nldf train student` with no flags trains the grid
/// teacher's recipe, at its own learning rate and for its own steps; under the MLP
/// teacher, at the MLP's.
#[test]
fn a_student_without_flags_takes_its_teachers_rate_and_steps() {
    use nldf_train::job::recipe::{
        DEMO_GRID_STUDENT_ITERS, DEMO_GRID_STUDENT_LR, DEMO_STUDENT_ITERS, DEMO_STUDENT_LR,
    };
    use nldf_train::trainers::config::{TeacherConfig, TeacherRunConfig};
    for (teacher, lr, iters) in [
        (
            TeacherConfig::grid(),
            DEMO_GRID_STUDENT_LR,
            DEMO_GRID_STUDENT_ITERS,
        ),
        (TeacherConfig::small(), DEMO_STUDENT_LR, DEMO_STUDENT_ITERS),
    ] {
        let run = tempfile::tempdir().unwrap();
        let teacher_dir = run.path().join(TEACHER_DIR);
        std::fs::create_dir(&teacher_dir).unwrap();
        let cfg = TeacherRunConfig {
            model: teacher,
            train: Default::default(),
        };
        std::fs::write(
            teacher_dir.join(CONFIG_FILE),
            serde_json::to_string(&cfg).unwrap(),
        )
        .unwrap();
        let run_arg = run.path().to_str().unwrap();
        let argv = ["nldf", "--data", "d", "--run", run_arg];
        let job = Cli::try_parse_from(argv).unwrap().student.job().unwrap();
        match job.source {
            StudentSource::Config(c) => {
                assert_eq!(c.train.lr, lr);
                assert_eq!(c.train.iters, iters);
                assert_eq!(c.train.lr_hold_steps + c.train.lr_decay_steps, iters);
            }
            _ => panic!("not the recipe"),
        }
    }
    assert_ne!(DEMO_GRID_STUDENT_LR, DEMO_STUDENT_LR);
    assert_ne!(DEMO_GRID_STUDENT_ITERS, DEMO_STUDENT_ITERS);
}
