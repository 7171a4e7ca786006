//! # mtpcr-core
//!
//! Multi-view point cloud registration by evolutionary multitasking (MTPCR; Wu et al., IEEE
//! TETCI). Three overlapping scans that form a loop are registered with no initial guess:
//! six populations evolve together (three original pairwise tasks whose loss adds a
//! loop-closure term, three easier aiding tasks) and share knowledge inside each pair and
//! across the loop.
//!
//! Pipeline: [`PointCloud`]s -> [`PreparedProblem`] (downsampled, centred, eps and shift,
//! search structures) -> evolution -> [`Registration`] with T12, T23, T31.
//!
//! **Convention.** `T_ij` maps points of cloud i into the frame of cloud j: `x_j = T_ij x_i`.
//!
//! ```
//! use mtpcr_core::{register, synthetic, Config};
//! let problem = synthetic::three_views(7, 6000);
//! let config = Config { generations: 5, population_size: 20, seed: Some(1), ..Config::default() };
//! let result = register(&problem.clouds, &config, None).unwrap();
//! let t12 = result.transforms[0]; // maps cloud 1 into cloud 2's frame
//! assert_eq!(result.history.len(), 6);
//! assert!(t12[(3, 3)] == 1.0);
//! ```
#![warn(missing_docs)]

pub mod cloud;
pub mod error;
pub mod eval;
mod evolve;
pub mod fitness;
pub mod io;
mod mfea;
mod refine;
pub mod registration;
pub mod se3;
pub mod synthetic;

pub use cloud::{PointCloud, Sampling};
pub use error::{Error, Result};
pub use evolve::TASK_NAMES;
pub use fitness::SearchMethod;
pub use registration::{
    register, BestCosts, Config, Method, Observer, PreparedProblem, Progress, Registration,
};
pub use se3::Transform;

/// The README's Rust example, compiled as a doctest so it cannot drift from the API.
#[doc = include_str!("../../../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
