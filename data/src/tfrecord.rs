//! TFRecord framing: `u64 LE length | u32 masked CRC32C(length) | data | u32 masked CRC32C(data)`,
//! with mask(c) = ((c >> 15) | (c << 17)) + 0xa282ead8 (model.md §11). Both CRCs are verified.

use std::io::{BufReader, Read, Write};
use std::path::{Path, PathBuf};

use crate::error::{DataError, Result};

/// TFRecord's masked CRC32C of `data`.
pub fn masked_crc32c(data: &[u8]) -> u32 {
    let c = crc32c::crc32c(data);
    c.rotate_right(15).wrapping_add(0xa282_ead8)
}

/// Appends one framed record to `w`.
pub fn write_record(w: &mut impl Write, data: &[u8]) -> std::io::Result<()> {
    let len = (data.len() as u64).to_le_bytes();
    w.write_all(&len)?;
    w.write_all(&masked_crc32c(&len).to_le_bytes())?;
    w.write_all(data)?;
    w.write_all(&masked_crc32c(data).to_le_bytes())
}

/// Frames `records` into one TFRecord byte buffer.
pub fn frame_records<'a>(records: impl IntoIterator<Item = &'a [u8]>) -> Vec<u8> {
    let mut out = vec![];
    for r in records {
        write_record(&mut out, r).expect("writing to a Vec cannot fail");
    }
    out
}

/// Streams the records of one TFRecord file; yields `(byte offset of the record, data)`.
pub struct TfRecordReader<R> {
    path: PathBuf,
    r: R,
    offset: u64,
    total: u64,
    failed: bool,
}

impl TfRecordReader<BufReader<std::fs::File>> {
    /// Opens a TFRecord file.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let f = std::fs::File::open(&path).map_err(|e| DataError::io(&path, e))?;
        let total = f.metadata().map_err(|e| DataError::io(&path, e))?.len();
        Ok(TfRecordReader {
            path,
            r: BufReader::with_capacity(1 << 20, f),
            offset: 0,
            total,
            failed: false,
        })
    }
}

impl<'a> TfRecordReader<&'a [u8]> {
    /// Reads records from memory; `path` is only used in error messages.
    pub fn from_slice(path: impl AsRef<Path>, bytes: &'a [u8]) -> Self {
        TfRecordReader {
            path: path.as_ref().to_path_buf(),
            r: bytes,
            offset: 0,
            total: bytes.len() as u64,
            failed: false,
        }
    }
}

impl<R: Read> TfRecordReader<R> {
    fn read_exact_at(&mut self, buf: &mut [u8], what: &str) -> Result<()> {
        self.r.read_exact(buf).map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                DataError::corrupt(
                    &self.path,
                    self.offset,
                    format!("file ends inside the {what} (truncated)"),
                )
            } else {
                DataError::io(&self.path, e)
            }
        })?;
        self.offset += buf.len() as u64;
        Ok(())
    }

    fn next_record(&mut self) -> Result<Option<(u64, Vec<u8>)>> {
        if self.offset == self.total {
            return Ok(None);
        }
        let start = self.offset;
        let mut head = [0u8; 12];
        self.read_exact_at(&mut head, "record header")?;
        let len_bytes: [u8; 8] = head[..8].try_into().expect("8 bytes");
        let len_crc = u32::from_le_bytes(head[8..].try_into().expect("4 bytes"));
        if masked_crc32c(&len_bytes) != len_crc {
            return Err(DataError::corrupt(
                &self.path,
                start,
                "length CRC mismatch in record header",
            ));
        }
        let len = u64::from_le_bytes(len_bytes);
        if len > self.total.saturating_sub(self.offset + 4) {
            return Err(DataError::corrupt(
                &self.path,
                start,
                format!(
                    "record length {len} runs past the end of the file ({} bytes; truncated?)",
                    self.total
                ),
            ));
        }
        let mut data = vec![0u8; len as usize];
        self.read_exact_at(&mut data, "record data")?;
        let crc_off = self.offset;
        let mut crc = [0u8; 4];
        self.read_exact_at(&mut crc, "record data CRC")?;
        if masked_crc32c(&data) != u32::from_le_bytes(crc) {
            return Err(DataError::corrupt(
                &self.path,
                crc_off,
                format!("data CRC mismatch for the record starting at byte {start}"),
            ));
        }
        Ok(Some((start, data)))
    }
}

impl<R: Read> Iterator for TfRecordReader<R> {
    type Item = Result<(u64, Vec<u8>)>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        let r = self.next_record().transpose();
        if matches!(r, Some(Err(_))) {
            self.failed = true;
        }
        r
    }
}
