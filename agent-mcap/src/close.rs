//! Closing an MCAP file that this crate writes.

use std::fs::File;
use std::io::BufWriter;

/// Finish `w` (its summary and footer) and flush what its buffer still holds
/// to the file. mcap's `Writer::finish` leaves that last flush to `Drop`,
/// which cannot report an error: a full disk would leave a file without its
/// footer while the writer said it was done.
pub(crate) fn close(mut w: mcap::Writer<BufWriter<File>>) -> Result<(), mcap::McapError> {
    w.finish()?;
    w.into_inner()
        .into_inner()
        .map(drop)
        .map_err(|e| mcap::McapError::Io(e.into_error()))
}
