//! Images: per-layer framebuffers, the layered EXR and PNG preview written atomically, and the
//! error metrics `compare` and `--reference` report.

pub mod components;
pub mod cryptomatte;
pub mod data;
pub mod denoise;
pub mod framebuffer;
pub mod layered_exr;
pub mod metrics;
pub mod noisy_patches;
pub mod output;
pub mod pixel_map;
pub mod preview;
pub mod region;
pub mod seams;
pub mod window;
