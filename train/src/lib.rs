//! nldf-train: training with candle. The audio encoder (AD-NeRF's AudioNet and AudioAttNet),
//! the audio-conditioned NeRF teacher, the NLDF light-segment ResMLP student, their losses,
//! the active beam pool and the trainers, with safetensors checkpoints and their configs.
//! Builds on nldf-core (rays, beams, data); nldf-export reads what it writes.
