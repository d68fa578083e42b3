//! The network presets the commands offer (`--preset`, `--depth`, `--student-depth`).

/// Teacher presets.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum TeacherPreset {
    /// 6 x 128, 32 samples inside the head's bounds: for 2-core machines.
    Small,
    /// AD-NeRF's 8 x 256 with 64 + 128 samples.
    AdNerf,
    /// 2 x 32, for tests and smoke runs.
    Tiny,
    /// The grid teacher: a multiresolution hash grid under a 2 x 64 network, 32 samples
    /// inside the head's bounds.
    Grid,
}

impl TeacherPreset {
    /// The preset's network configuration.
    pub fn config(self) -> nldf_train::trainers::config::TeacherConfig {
        use nldf_train::trainers::config::TeacherConfig;
        match self {
            TeacherPreset::Small => TeacherConfig::small(),
            TeacherPreset::AdNerf => TeacherConfig::ad_nerf(),
            TeacherPreset::Tiny => TeacherConfig::tiny(),
            TeacherPreset::Grid => TeacherConfig::grid(),
        }
    }
}

/// The teacher a recipe trains (`nldf demo --teacher`, `nldf train --data --teacher`).
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TeacherRecipe {
    /// AD-NeRF's MLP on frequency-encoded points (6 x 128), 1100 steps, its student 4500:
    /// the quicker recipe, about a quarter of the grid recipe's minutes.
    Mlp,
    /// A multiresolution hash grid under a 2 x 64 network, 2400 steps in the MLP teacher's
    /// minutes, its student 36000: sharper, the student's steps eight times as long.
    #[default]
    Grid,
}

impl TeacherRecipe {
    /// The library's name for it.
    pub fn kind(self) -> nldf_train::job::recipe::TeacherKind {
        use nldf_train::job::recipe::TeacherKind;
        match self {
            TeacherRecipe::Mlp => TeacherKind::Mlp,
            TeacherRecipe::Grid => TeacherKind::Grid,
        }
    }
}

/// Student presets: the paper's depths of Table 3 (width 256), nldf's own, and a tiny one
/// for smoke runs.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum StudentPreset {
    #[value(name = "28")]
    D28,
    #[value(name = "50")]
    D50,
    #[value(name = "88")]
    D88,
    /// 28 layers at width 128: about three times the steps of 28 x 256 in the same time,
    /// and the demo's student.
    #[value(name = "28x128")]
    D28W128,
    /// 16 x 128 with K = 8 beam points: the real-time preset, and the demo's student.
    Realtime,
    /// 6 x 32 with 4 beam points: tests and smoke runs.
    Tiny,
}

impl StudentPreset {
    /// The preset's network configuration.
    pub fn config(self) -> nldf_train::networks::student::StudentConfig {
        use nldf_train::networks::student::StudentConfig;
        match self {
            StudentPreset::D28 => StudentConfig::paper_d28(),
            StudentPreset::D50 => StudentConfig::paper_d50(),
            StudentPreset::D88 => StudentConfig::paper_d88(),
            StudentPreset::D28W128 => StudentConfig {
                width: 128,
                ..StudentConfig::paper_d28()
            },
            StudentPreset::Realtime => StudentConfig::realtime(),
            StudentPreset::Tiny => StudentConfig::tiny(),
        }
    }
}
