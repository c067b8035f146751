//! Reading input files: regular files only, and no more than their size when opened. Every
//! reader of tress's inputs (scenes, hair, meshes, images, studies, pieces) opens them here.

use std::fs::{File, OpenOptions};
use std::io::{Error, ErrorKind, Read};
use std::path::Path;

/// The error for a path that is no regular file; a directory has its own kind, so that callers
/// can tell it apart (Python raises `IsADirectoryError`).
fn not_regular(metadata: &std::fs::Metadata) -> Error {
    if metadata.is_dir() {
        Error::new(ErrorKind::IsADirectory, "a directory, not a regular file")
    } else {
        Error::new(
            ErrorKind::InvalidInput,
            "not a regular file (a device or pipe)",
        )
    }
}

/// `path` opened for reading if it is a regular file. Devices, FIFOs and directories are
/// refused without blocking: opening a FIFO waits for a writer, which may never come.
pub fn open_regular(path: &Path) -> std::io::Result<File> {
    let metadata = std::fs::metadata(path)?;
    if !metadata.is_file() {
        return Err(not_regular(&metadata));
    }
    let mut options = OpenOptions::new();
    options.read(true);
    // Should the path become a FIFO after the check, the open still returns at once (the flag
    // changes nothing for a regular file) and the check below refuses it.
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::custom_flags(&mut options, libc::O_NONBLOCK);
    let file = options.open(path)?;
    let metadata = file.metadata()?;
    if !metadata.is_file() {
        return Err(not_regular(&metadata));
    }
    Ok(file)
}

/// The whole of a regular file ([`open_regular`]). A symlink to `/dev/zero` given as a hair
/// file grew the process to many GB; a file growing while it is read is read up to the size it
/// had when opened.
pub fn read_regular(path: &Path) -> std::io::Result<Vec<u8>> {
    let file = open_regular(path)?;
    let len = file.metadata()?.len();
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(len).read_to_end(&mut bytes)?;
    Ok(bytes)
}

/// [`read_regular`] as UTF-8 text.
pub fn read_regular_text(path: &Path) -> std::io::Result<String> {
    String::from_utf8(read_regular(path)?).map_err(|e| Error::new(ErrorKind::InvalidData, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_files_are_read_and_special_files_refused() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("a.txt");
        std::fs::write(&file, "hair").unwrap();
        assert_eq!(read_regular_text(&file).unwrap(), "hair");
        let err = read_regular(dir.path()).unwrap_err();
        assert!(err.to_string().contains("not a regular file"), "{err}");
        assert_eq!(err.kind(), ErrorKind::IsADirectory);
        #[cfg(unix)]
        {
            let link = dir.path().join("zero.hair");
            std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
            let err = read_regular(&link).unwrap_err();
            assert!(err.to_string().contains("not a regular file"), "{err}");
            let fifo = dir.path().join("fifo.hair");
            let made = std::process::Command::new("mkfifo")
                .arg(&fifo)
                .status()
                .unwrap();
            assert!(made.success());
            let err = open_regular(&fifo).unwrap_err();
            assert!(err.to_string().contains("not a regular file"), "{err}");
        }
    }
}
