//! Input files read whole, bounded before they are read: a file that is not a regular file (a
//! FIFO, a device such as `/dev/zero`, a directory) or that is larger than its kind allows is
//! refused with what it is and what is allowed, instead of being read until memory runs out
//! (`polydem check /dev/zero` once grew to 16.6 GB in a minute).

use std::fs::File;
use std::io::{self, Read};
use std::path::Path;

/// The kinds of input files and the most bytes each may have.
#[derive(Clone, Copy, Debug)]
pub enum InputKind {
    /// A scene (TOML): 16 MiB, thousands of times the largest shipped scene.
    Scene,
    /// A packing (`polydem pack`, about 125 bytes a particle): 16 GiB, some 10⁸ particles.
    Packing,
    /// A particle or wall mesh (STL, OBJ): 2 GiB.
    Mesh,
    /// A probe input (JSON): 64 MiB.
    Probe,
}

impl InputKind {
    /// The most bytes a file of this kind may have.
    pub const fn limit(self) -> u64 {
        match self {
            InputKind::Scene => 16 << 20,
            InputKind::Packing => 16 << 30,
            InputKind::Mesh => 2 << 30,
            InputKind::Probe => 64 << 20,
        }
    }

    fn name(self) -> &'static str {
        match self {
            InputKind::Scene => "a scene file",
            InputKind::Packing => "a packing file",
            InputKind::Mesh => "a mesh file",
            InputKind::Probe => "a probe file",
        }
    }
}

/// What a path is when it is not a regular file.
fn file_type_name(t: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if t.is_dir() {
        "a directory"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

/// Reads `path` whole when it is a regular file of at most `kind`'s limit; the error says
/// otherwise what it is (callers name the path).
pub fn read_bounded(path: &Path, kind: InputKind) -> io::Result<Vec<u8>> {
    let not_regular = |t: std::fs::FileType| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "{} ({} must be a regular file)",
                file_type_name(t),
                kind.name()
            ),
        )
    };
    // Looked at before it is opened: opening a FIFO blocks until something writes to it.
    let t = std::fs::metadata(path)?.file_type();
    if !t.is_file() {
        return Err(not_regular(t));
    }
    let file = File::open(path)?;
    let meta = file.metadata()?;
    if !meta.file_type().is_file() {
        return Err(not_regular(meta.file_type()));
    }
    let limit = kind.limit();
    let too_large = |size: u64| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "{size} bytes, more than the {limit} bytes {} may have",
                kind.name()
            ),
        )
    };
    if meta.len() > limit {
        return Err(too_large(meta.len()));
    }
    // Read at most one byte past the limit: a file that grows while it is read is still
    // bounded.
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// [`read_bounded`] as UTF-8 text.
pub fn read_bounded_text(path: &Path, kind: InputKind) -> io::Result<String> {
    String::from_utf8(read_bounded(path, kind)?).map_err(|e| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A device, a FIFO and a directory are refused by what they are, before a byte is read;
    /// a regular file within the limit is read, one past it refused with its size.
    #[test]
    fn only_regular_files_within_the_limit_are_read() {
        let err = read_bounded(Path::new("/dev/zero"), InputKind::Scene).unwrap_err();
        assert!(err.to_string().contains("a character device"), "{err}");
        let dir = std::env::temp_dir().join(format!("polydem-bounded-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let err = read_bounded(&dir, InputKind::Scene).unwrap_err();
        assert!(err.to_string().contains("a directory"), "{err}");
        let fifo = dir.join("fifo");
        let _ = std::fs::remove_file(&fifo);
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            // Refused without being opened (opening it would wait for a writer).
            let err = read_bounded(&fifo, InputKind::Scene).unwrap_err();
            assert!(err.to_string().contains("a FIFO"), "{err}");
        }
        let file = dir.join("scene.toml");
        std::fs::write(&file, "x".repeat(100)).unwrap();
        assert_eq!(read_bounded(&file, InputKind::Scene).unwrap().len(), 100);
        std::fs::write(&file, vec![b'x'; (InputKind::Scene.limit() + 1) as usize]).unwrap();
        let err = read_bounded(&file, InputKind::Scene).unwrap_err();
        assert!(
            err.to_string()
                .contains("16777217 bytes, more than the 16777216 bytes a scene file"),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
