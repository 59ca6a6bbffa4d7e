//! Errors raised while reading scenes and volume files.
//!
//! Every variant names the file (or the field) at fault, so that a message
//! shown to an artist says where to look and what is wrong.

use std::path::PathBuf;

/// Anything that can go wrong while loading or validating a scene.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read at all (missing, unreadable).
    ///
    /// The reason is part of the message and not also exposed as the error's
    /// source, so that a chain printed in full (`{:#}` through `anyhow`)
    /// says it once.
    #[error("cannot read {path}: {reason}")]
    Io {
        /// The file that could not be read.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// The scene file is not valid RON for a Lantern scene (syntax, unknown
    /// or missing field, wrong type).
    #[error("{path}: {message}")]
    Parse {
        /// The scene file.
        path: PathBuf,
        /// The parser's message with line and column.
        message: String,
    },
    /// A value in the scene is out of its allowed range.
    #[error("{path}: invalid {field}: {reason}")]
    Invalid {
        /// The scene file (or `<memory>` for scenes built in code).
        path: PathBuf,
        /// The field at fault, as it is written in the scene file.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A volume file is malformed: bad magic, truncated data, inconsistent
    /// header, unsupported encoding, or a failure inside the reader.
    #[error("volume file {path}: {reason}")]
    Volume {
        /// The volume (or header) file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// An environment map is unusable: unreadable or truncated, not a
    /// latitude–longitude map, or with texels that are not finite and
    /// non-negative.
    #[error("environment map {path}: {reason}")]
    Environment {
        /// The map file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// The scene could not be written.
    #[error("cannot write {path}: {reason}")]
    Write {
        /// The destination.
        path: PathBuf,
        /// Why it failed.
        reason: String,
    },
    /// A file could not be written whole; the previous one is unchanged.
    #[error(transparent)]
    WriteFile(#[from] crate::atomic::WriteError),
}

impl SceneError {
    /// Shorthand for [`SceneError::Invalid`].
    pub fn invalid(path: impl Into<PathBuf>, field: &str, reason: impl Into<String>) -> Self {
        Self::Invalid {
            path: path.into(),
            field: field.to_owned(),
            reason: reason.into(),
        }
    }

    /// Shorthand for [`SceneError::Environment`].
    pub fn environment(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Self::Environment {
            path: path.into(),
            reason: reason.into(),
        }
    }

    /// Shorthand for [`SceneError::Volume`].
    pub fn volume(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Self::Volume {
            path: path.into(),
            reason: reason.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A missing file's error, printed as the command line prints it (the
    /// whole `anyhow` chain), names the file and gives the reason once.
    #[test]
    fn io_error_says_its_reason_once() {
        let reason = std::fs::read("/nonexistent/lantern/scene.ron").unwrap_err();
        let text = reason.to_string();
        let err = anyhow::Error::from(SceneError::Io {
            path: PathBuf::from("/nonexistent/lantern/scene.ron"),
            reason,
        });
        let printed = format!("{err:#}");
        assert!(
            printed.contains("/nonexistent/lantern/scene.ron"),
            "{printed}"
        );
        assert_eq!(printed.matches(&text).count(), 1, "{printed}");
    }
}
