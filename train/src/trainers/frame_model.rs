//! A trained model that renders whole frames ([`FrameModel`]: the teacher, the student, the
//! upsampled student, and the benchmarks' runtimes), and a student's names from its config
//! for tables and plots.

use nldf_core::beam::BeamSpec;
use nldf_core::dataset::Frame;
use nldf_core::image::ImageRgb;

use crate::error::Result;
use crate::trainers::config::{StudentRunConfig, StudentTrainConfig};
use crate::trainers::data::TrainData;

/// A trained model that renders whole frames.
pub trait FrameModel {
    /// Short name: the folder of its renders (`teacher`, `student`).
    fn label(&self) -> String;
    /// What it is, for tables.
    fn describe(&self) -> String;
    /// Training steps done.
    fn step(&self) -> usize;
    /// Multiply-adds per ray that meets the head's bounds (the others cost none).
    fn macs_per_ray(&self) -> f64;
    /// Multiply-adds a frame costs beyond [`FrameModel::macs_per_ray`] times its hits (an
    /// upsampler's mouth patch: its rays at the student's cost); none by default.
    fn extra_macs(&self, _data: &TrainData, _frame: &Frame) -> f64 {
        0.0
    }
    fn render_frame(&self, data: &TrainData, frame: &Frame) -> Result<ImageRgb>;
}

/// A student's name from its config: the network's shape, then its recipe where it is not
/// the default one (pixels only, pseudo views and their share, the segment term's lambda,
/// mouth rays, the learning rate, weight averaging, no pool), so that students trained
/// differently never print alike.
pub fn student_name(cfg: &StudentRunConfig) -> String {
    let (m, t) = (&cfg.model, &cfg.train);
    let defaults = StudentTrainConfig::default();
    let mut name = format!("student {}x{}", m.depth, m.width);
    if m.beam.n_points != BeamSpec::default().n_points {
        name.push_str(&format!(" (K = {})", m.beam.n_points));
    }
    let mut recipe = Vec::new();
    if !t.distill {
        recipe.push("pixels only".to_string());
    } else if t.pseudo_frames > 0 {
        let rays = if t.pseudo_rays > 0 {
            format!(" of {} px", t.pseudo_rays)
        } else {
            String::new()
        };
        recipe.push(format!(
            "{} pseudo views{rays} at {}x",
            t.pseudo_frames, t.pose_range
        ));
        if t.pseudo_fraction != defaults.pseudo_fraction {
            recipe.push(format!("mix {}", t.pseudo_fraction));
        }
    }
    if t.distill && t.lambda != defaults.lambda {
        recipe.push(format!("lambda {}", t.lambda));
    }
    if t.distill && t.opacity_floor != defaults.opacity_floor {
        recipe.push(format!("opacity floor {}", t.opacity_floor));
    }
    if t.mouth_fraction != defaults.mouth_fraction {
        recipe.push(format!("mouth {}", t.mouth_fraction));
    }
    if t.lr != defaults.lr {
        recipe.push(format!("lr {}", t.lr));
    }
    if t.ema_decay != defaults.ema_decay {
        recipe.push(format!("weights averaged at {}", t.ema_decay));
    }
    if t.audio_lr_scale != defaults.audio_lr_scale {
        recipe.push(format!("audio encoder at {}x the rate", t.audio_lr_scale));
    }
    if !t.pool {
        recipe.push("no pool".into());
    }
    if let (Some(a), nldf_core::audio::FeatureSource::Nldf(f)) = (m.audio.ahead, &m.audio.features)
    {
        recipe.push(format!("audio {:.1} ms ahead", 1e3 * f.lookahead_s(a)));
    }
    for r in recipe {
        name.push_str(", ");
        name.push_str(&r);
    }
    name
}

/// A student's short name for plots, from its config: shape, then `pixels`, `distilled`
/// or `N pseudo` (and `no pool`).
pub fn student_short_name(cfg: &StudentRunConfig) -> String {
    let (m, t) = (&cfg.model, &cfg.train);
    let mut name = format!("{}x{}", m.depth, m.width);
    if m.beam.n_points != BeamSpec::default().n_points {
        name.push_str(&format!(" K{}", m.beam.n_points));
    }
    name.push(' ');
    name.push_str(&match (t.distill, t.pseudo_frames) {
        (false, _) => "pixels".to_string(),
        (true, 0) => "distilled".to_string(),
        (true, n) => format!("{n} pseudo"),
    });
    if !t.pool {
        name.push_str(", no pool");
    }
    name
}

#[cfg(test)]
mod tests {
    use super::*;
    use nldf_core::beam::BeamAnchor;

    #[test]
    fn students_trained_differently_are_named_differently() {
        let base = StudentRunConfig::default();
        let mut pixels = base.clone();
        pixels.train.distill = false;
        let mut pseudo = base.clone();
        pseudo.train.pseudo_frames = 2000;
        let mut thin = pseudo.clone();
        thin.train.pseudo_rays = 0;
        let mut mix = pseudo.clone();
        mix.train.pseudo_fraction = 0.75;
        mix.train.mouth_fraction = 0.2;
        let names: Vec<String> = [&base, &pixels, &pseudo, &thin, &mix]
            .into_iter()
            .map(student_name)
            .collect();
        for (a, name) in names.iter().enumerate() {
            for other in &names[a + 1..] {
                assert_ne!(name, other);
            }
        }
        assert!(names[1].contains(", pixels only"), "{}", names[1]);
        let short: Vec<String> = [&base, &pixels, &pseudo]
            .into_iter()
            .map(student_short_name)
            .collect();
        assert_eq!(
            short[1],
            format!("{}x{} pixels", base.model.depth, base.model.width)
        );
        assert!(short[0].ends_with(" distilled") && short[2].ends_with(" 2000 pseudo"));
        assert!(
            names[4].contains("2000 pseudo views of 1024 px at 2x, mix 0.75, mouth 0.2"),
            "{}",
            names[4]
        );
    }

    fn run_config() -> StudentRunConfig {
        let mut cfg = StudentRunConfig {
            model: crate::networks::student::StudentConfig::realtime(),
            ..StudentRunConfig::default()
        };
        cfg.model.beam.anchor = Some(BeamAnchor {
            centre: [0.0; 3],
            distance: 1.0,
        });
        cfg.train.pseudo_frames = 600;
        cfg.train.pseudo_rays = 1024;
        cfg.train.pseudo_fraction = 0.75;
        cfg
    }

    #[test]
    fn lambda_and_the_opacity_floor_are_named() {
        let base = run_config();
        assert_eq!(
            student_name(&base),
            "student 16x128 (K = 8), 600 pseudo views of 1024 px at 2x, mix 0.75"
        );
        let mut lambda = base.clone();
        lambda.train.lambda = 0.0;
        let mut pixels = base.clone();
        pixels.train.distill = false;
        pixels.train.lambda = 0.0;
        let mut floored = base.clone();
        floored.train.opacity_floor = 0.05;
        let mut faster = base.clone();
        faster.train.lr = 1e-3;
        let mut averaged = base.clone();
        averaged.train.ema_decay = 0.998;
        let names: Vec<String> = [&base, &lambda, &pixels, &floored, &faster, &averaged]
            .iter()
            .map(|c| student_name(c))
            .collect();
        assert!(names[1].ends_with(", lambda 0"), "{}", names[1]);
        // Without distillation lambda weighs nothing, so it is not named.
        assert_eq!(names[2], "student 16x128 (K = 8), pixels only");
        assert!(names[3].ends_with(", opacity floor 0.05"), "{}", names[3]);
        assert!(names[4].ends_with(", lr 0.001"), "{}", names[4]);
        assert!(
            names[5].ends_with(", weights averaged at 0.998"),
            "{}",
            names[5]
        );
        for (i, a) in names.iter().enumerate() {
            for b in &names[i + 1..] {
                assert_ne!(a, b);
            }
        }
    }
}
