//! Reading input files: regular files only, and no more than their size when opened.

use std::io::{Error, ErrorKind, Read};
use std::path::Path;

/// The whole of a regular file. Devices, FIFOs and directories are refused (a symlink to
/// `/dev/zero` given as a hair file grew the process to many GB), and a file growing while it
/// is read is read up to the size it had when opened.
pub fn read_regular(path: &Path) -> std::io::Result<Vec<u8>> {
    let file = std::fs::File::open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(Error::new(
            ErrorKind::InvalidInput,
            "not a regular file (a directory, device or pipe)",
        ));
    }
    let len = meta.len();
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
        #[cfg(unix)]
        {
            let link = dir.path().join("zero.hair");
            std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
            let err = read_regular(&link).unwrap_err();
            assert!(err.to_string().contains("not a regular file"), "{err}");
        }
    }
}
