//! The one error type of mtpcr. Every failure caused by user input is a variant here; the
//! library never panics on user input.

use std::path::PathBuf;

/// Everything that can go wrong in mtpcr, with enough context to tell the user what to fix.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A point cloud was given with no points.
    #[error("{cloud}: the point cloud is empty")]
    EmptyCloud {
        /// Which cloud ("cloud 1", a file name, ...).
        cloud: String,
    },
    /// A point cloud has too few points for the method.
    #[error("{cloud}: {points} points, but at least {needed} are needed")]
    TooFewPoints {
        /// Which cloud.
        cloud: String,
        /// Points it has.
        points: usize,
        /// Points needed.
        needed: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("{cloud}: point {index} has a non-finite coordinate ({value})")]
    NonFiniteCoordinate {
        /// Which cloud.
        cloud: String,
        /// Index of the first bad point.
        index: usize,
        /// The bad value, printed.
        value: String,
    },
    /// A coordinate is so large (beyond [`crate::cloud::MAX_COORDINATE`] in absolute value) that
    /// distances or squared distances would overflow.
    #[error(
        "{cloud}: point {index} has a coordinate too large to register ({value}; the limit is \
         {limit} in absolute value): rescale or re-centre the cloud"
    )]
    CoordinateTooLarge {
        /// Which cloud.
        cloud: String,
        /// Index of the first bad point.
        index: usize,
        /// The bad value, printed.
        value: String,
        /// The largest magnitude accepted, printed.
        limit: String,
    },
    /// Every point lies on one line, so the rotation about that line cannot be determined.
    #[error(
        "{cloud}: all points lie on one line (the rotation about it cannot be determined); \
         a cloud must extend in at least two directions"
    )]
    CollinearCloud {
        /// Which cloud.
        cloud: String,
    },
    /// The cloud has no spatial extent (every point identical), so no spacing can be derived.
    #[error("{cloud}: all points are identical (the cloud has no extent)")]
    DegenerateCloud {
        /// Which cloud.
        cloud: String,
    },
    /// A configuration value is out of its range.
    #[error("invalid setting `{field}`: {problem}")]
    InvalidConfig {
        /// The config field's name (the same in Rust, Python, CLI flags and config files).
        field: &'static str,
        /// What is wrong and what is allowed.
        problem: String,
    },
    /// A setting was given by a name that is not a field of `Config`.
    #[error("unknown setting `{name}` (settings are: {known})")]
    UnknownSetting {
        /// The name given.
        name: String,
        /// The known names, comma separated.
        known: String,
    },
    /// A file could not be opened, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A file was read but its content is not what it should be.
    #[error("{}: {problem}", path.display())]
    MalformedFile {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        problem: String,
    },
    /// The caller interrupted the registration (see `Interrupt`).
    #[error("interrupted")]
    Interrupted,
    /// Any other invalid argument (a transform that is not rigid, mismatched lengths, ...).
    #[error("{0}")]
    InvalidInput(String),
}

/// Result alias used throughout mtpcr.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub(crate) fn config(field: &'static str, problem: impl Into<String>) -> Self {
        Error::InvalidConfig {
            field,
            problem: problem.into(),
        }
    }

    /// `Ok` when `ok`, else the error "`field` must be `rule`, got `value`" (the range checks
    /// of every settings struct).
    pub(crate) fn check_setting(
        ok: bool,
        field: &'static str,
        rule: &str,
        value: impl std::fmt::Display,
    ) -> Result<()> {
        if ok {
            Ok(())
        } else {
            Err(Error::config(field, format!("must be {rule}, got {value}")))
        }
    }

    pub(crate) fn malformed(path: impl Into<PathBuf>, problem: impl Into<String>) -> Self {
        Error::MalformedFile {
            path: path.into(),
            problem: problem.into(),
        }
    }

    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}
