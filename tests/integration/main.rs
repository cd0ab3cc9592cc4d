//! The integration tests, one test binary: `cargo test --release --test integration`, or one
//! module of it with a filter (`cargo test --release --test integration cli_stages::`).
//!
//! The CLI as a user (or a Makefile) runs it, and every file it writes opened by the
//! independent tools (usd-core, the Khronos glTF validator, three.js in Chromium, Blender's bpy). Shared
//! helpers are in [`common`].

mod common;

mod attributes;
mod blend;
mod blender;
mod cache_bake;
mod cache_clip;
mod cache_fit;
mod cache_honest;
mod cli_budget;
mod cli_cage;
mod cli_cluster;
mod cli_contacts;
mod cli_conventions;
mod cli_degenerate;
mod cli_errors;
mod cli_interrupt;
mod cli_output;
mod cli_physics;
mod cli_scale;
mod cli_stages;
mod cli_threads;
mod cli_timing;
mod cli_warnings;
mod export_formats;
mod fixtures;
mod keyframe_clip;
mod layers;
mod normals;
mod paper_scenes;
mod render_demo;
mod report_html;
mod studio_caches;
mod texture;
mod vertex_numbers;
mod warm_rebake;
mod weld_keys;
