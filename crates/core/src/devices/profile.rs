//! What a device profile's text can get wrong. Profiles parse text into plain types; reading
//! the files is the configuration's job, so the error names the file it was given and the
//! key, and carries the fix.

use std::path::{Path, PathBuf};

/// A device profile that does not parse or does not hold together.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProfileError {
    /// Not valid TOML, or not the profile's schema.
    #[error("{}: {message}\nfix: {}", .file.display(), toml_fix(.message))]
    Parse {
        /// The profile's file.
        file: PathBuf,
        /// The TOML parser's message, which names the key and line.
        message: String,
    },
    /// A value is out of range or inconsistent.
    #[error("{}: key `{key}`: {problem}; fix: {fix}", .file.display())]
    Invalid {
        /// The profile's file.
        file: PathBuf,
        /// Dotted key path.
        key: String,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },
}

impl ProfileError {
    /// A TOML parser's error for `file`.
    pub fn parse(file: &Path, error: &toml::de::Error) -> Self {
        Self::Parse {
            file: file.to_owned(),
            message: error.to_string(),
        }
    }

    /// A value that is out of range or inconsistent.
    pub fn invalid(file: &Path, key: &str, problem: impl Into<String>, fix: &str) -> Self {
        Self::Invalid {
            file: file.to_owned(),
            key: key.to_owned(),
            problem: problem.into(),
            fix: fix.to_owned(),
        }
    }
}

/// The fix for a TOML parser's message, chosen by the serde error kind it names.
pub fn toml_fix(message: &str) -> &'static str {
    if message.contains("unknown field") {
        "remove the key or correct its spelling; the keys allowed there are listed above"
    } else if message.contains("missing field") {
        "add the key; docs/configuration.md lists every key, and devices/ has an example of \
         each kind of file"
    } else if message.contains("unknown variant") {
        "use one of the values listed above, spelt as there"
    } else if message.contains("invalid type") || message.contains("invalid value") {
        "give the value the type named above (text in quotes, numbers and true/false without)"
    } else {
        "correct the TOML at the line shown (each key = value on its own line, [sections] and \
         [[lists]] in brackets)"
    }
}
