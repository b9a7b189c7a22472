//! What goes wrong loading a scene: key-level problems and the error that lists them, each with
//! its file, dotted key and line.

/// A key-level problem found in a scene file.
#[derive(Clone, Debug, PartialEq)]
pub struct KeyError {
    /// Full dotted key, e.g. `walls[1].motion.rpm` (empty for the document itself).
    pub key: String,
    /// 1-based line of the key in the file, when it is in the file.
    pub line: Option<usize>,
    /// What is wrong and what is allowed.
    pub message: String,
}

/// Errors reading a scene or inserting its particles. Every one names the scene file.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{file}: cannot read the scene file: {message}")]
    Read { file: String, message: String },
    /// Not valid TOML.
    #[error("{file}:{line}:{column}: TOML syntax error: {message}")]
    Syntax {
        file: String,
        line: usize,
        column: usize,
        message: String,
    },
    /// Valid TOML, but keys or values are wrong; all problems found are listed.
    #[error("{}", format_key_errors(file, errors))]
    Invalid { file: String, errors: Vec<KeyError> },
    /// Particles could not be placed as asked.
    #[error("{file}: {key}: {message}")]
    Insertion {
        file: String,
        key: String,
        message: String,
    },
}

impl SceneError {
    /// The dotted keys the error names (empty for read and syntax errors).
    pub fn keys(&self) -> Vec<&str> {
        match self {
            SceneError::Invalid { errors, .. } => errors.iter().map(|e| e.key.as_str()).collect(),
            SceneError::Insertion { key, .. } => vec![key.as_str()],
            _ => Vec::new(),
        }
    }
}

fn format_key_errors(file: &str, errors: &[KeyError]) -> String {
    let one = |e: &KeyError| {
        let loc = e
            .line
            .map_or_else(|| file.to_string(), |l| format!("{file}:{l}"));
        if e.key.is_empty() {
            format!("{loc}: {}", e.message)
        } else {
            format!("{loc}: {}: {}", e.key, e.message)
        }
    };
    match errors {
        [e] => one(e),
        _ => {
            let mut s = format!("{file}: {} errors in the scene file:", errors.len());
            for e in errors {
                s.push_str("\n  ");
                s.push_str(&one(e));
            }
            s
        }
    }
}
