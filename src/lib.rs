//! icrender: a renderer for global illumination with Ward's irradiance cache, split into
//! Radiance's components (emission, direct, specular, indirect diffuse).

// Every `unsafe` block lives in `sys`, the wrappers of the foreign libraries.
#![deny(unsafe_code)]

pub mod checkpoint;
pub mod cli;
pub mod codec;
pub mod commands;
pub mod diagnostics;
pub mod export;
pub mod frames;
pub mod image;
pub mod irradiance;
pub mod job;
pub mod memory;
pub mod parallel;
pub mod prepass;
pub mod progress;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod shading;
pub mod stats;
#[allow(unsafe_code)]
pub mod sys;
pub mod tiles;
pub mod tracer;
