//! The integration tests, one module per subject, in one test binary so
//! the library is linked once (issue 14). `cargo test --test all NAME`
//! runs a subset, e.g. `cargo test --test all traverse::`.
//!
//! `common` holds the helpers every module shares. The fuzz targets stay a
//! binary of their own (tests/fuzz.rs): they watch the largest allocation
//! with a counting global allocator, which only means something in a
//! process where no other test allocates at the same time.
//!
//! Proptest persists failures of a module `tests/all/X.rs` to
//! `tests/proptest-regressions/X.txt` (its default `SourceParallel`
//! persistence: the sibling of the folder holding `main.rs`) and replays
//! them first on every run.

mod common;

// The binary's command line, compiled here so that a test can walk every
// option clap knows (cli_numbers).
#[path = "../../src/cli/mod.rs"]
#[allow(dead_code, unused_imports)]
mod cli;

mod bad_input;
mod batch;
mod byte_planes;
mod cli_help;
mod cli_numbers;
mod clip;
mod composite;
mod cull;
mod data_extremes;
mod dda_planes;
mod demo_sheet;
mod dicom;
mod experiments;
mod explore;
mod extremes;
mod formats;
mod framing;
mod gallery;
mod generators;
mod harden;
mod harden_batch;
mod harden_flips;
mod harden_json;
mod harden_memory;
mod harden_options;
mod harden_reader;
mod hostile_dicom;
mod hostile_outputs;
mod hostile_readers;
mod hostile_serve;
mod input_kinds;
mod integrators;
mod labels;
mod layout;
mod library;
mod mip;
mod modality;
mod no_debug_text;
mod normals;
mod one_look;
mod orient;
mod phantom_mr;
mod prep;
mod prep_shard;
mod real_data;
mod reference;
mod render;
mod scene;
mod serve;
mod shadow_acne;
mod shard;
mod template;
mod traverse;
mod wood_grain;
