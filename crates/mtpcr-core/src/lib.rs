//! # mtpcr-core
//!
//! Multi-view point cloud registration by evolutionary multitasking (MTPCR; Wu et al., IEEE
//! TETCI): overlapping scans are registered with no initial guess. Each edge of a view graph
//! (a pair of scans) is a pair of tasks, the original one (inlier ratio, plus a loop-closure
//! term on a loop) and an easier aiding one; their populations evolve together and share
//! knowledge inside each pair and around the loop.
//!
//! Pipeline: [`PointCloud`]s -> [`PreparedProblem`] (downsampled, centred, eps and shift,
//! search structures, a [`ViewGraph`]) -> evolution of every edge -> joint refinement ->
//! [`Registration`] with one estimate per edge and one pose per view. `ARCHITECTURE.md` in
//! this crate's folder maps the modules.
//!
//! **Convention.** `T_ij` maps points of cloud i into the frame of cloud j: `x_j = T_ij x_i`;
//! an edge's transform is named `t_target_source`.
//!
//! ```
//! use mtpcr_core::{register, synthetic, Config};
//! let problem = synthetic::three_views(7, 6000);
//! let config = Config { generations: 5, population_size: 20, seed: Some(1), ..Config::default() };
//! let result = register(&problem.clouds, &config, None).unwrap();
//! let t12 = result.edges[0].t_target_source; // maps cloud 1 into cloud 2's frame
//! assert_eq!((result.edges[0].source, result.edges[0].target), (0, 1));
//! assert_eq!(result.history.len(), 5 + 1, "the kept evolution: initial population and 5 generations");
//! assert!(result.loop_residual().unwrap() < 1e-9, "the refinement closes the loop");
//! assert_eq!(result.t_target_source(1, 0), Some(t12));
//! // `result.verdict.confident` says whether to believe it (5 generations of 20: no promise).
//! ```
#![warn(missing_docs)]

mod angle;
pub mod cloud;
pub mod config;
mod ea;
pub mod error;
pub mod eval;
pub mod features;
mod freespace;
pub mod graph;
pub mod interrupt;
pub mod io;
pub mod loss;
mod multiview;
mod posegraph;
pub mod problem;
mod refine;
mod register;
pub mod result;
pub mod screening;
pub mod se3;
pub mod search;
pub mod synthetic;
pub mod verdict;

pub use cloud::{PointCloud, Sampling};
pub use config::{Config, Method, Order};
pub use ea::{Observer, Progress, Stage};
pub use error::{Error, Result};
pub use graph::{Edge, ViewGraph};
pub use interrupt::Interrupt;
pub use problem::{PreparedProblem, MIN_POINTS};
pub use register::{register, register_interruptible, register_screened, screen_pairs};
pub use result::{EdgeEstimate, Registration, Unplaced};
pub use screening::{ScreenedPair, Screening};
pub use se3::Transform;
pub use search::SearchMethod;
pub use verdict::Verdict;

/// The README's Rust example, compiled as a doctest so it cannot drift from the API.
#[doc = include_str!("../../../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
