//! The crate's one error type. Every message names the file (or the argument), the field and the
//! offending value, so a user can fix the input without a debugger. Nothing here panics.

use std::path::Path;

/// Errors of the `events` crate.
#[derive(Debug, thiserror::Error)]
pub enum EventsError {
    /// An operating-system I/O error while reading or writing `path`.
    #[error("{path}: I/O error: {source}")]
    Io {
        /// File being read or written.
        path: String,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The file's content does not follow its format (wrong magic, truncated record, absurd header
    /// value, unparsable line ...).
    #[error("{path}: {message}")]
    Format {
        /// File being read (or `"<memory>"` for in-memory buffers).
        path: String,
        /// What is wrong, naming the field and the value.
        message: String,
    },
    /// A word of a Prophesee EVT 2.0 / 3.0 stream that its specification does not allow there
    /// (reserved type, event outside the sensor, event without a row, vector without a base, time
    /// going backwards).
    #[error("{path}: byte {offset}: {message}")]
    BadWord {
        /// File being read.
        path: String,
        /// Byte offset of the word in the file (header included).
        offset: u64,
        /// What is wrong, naming the word and the value.
        message: String,
    },
    /// Timestamps decrease at `index` (use [`crate::EventStream::sort_by_time`] to repair).
    #[error(
        "timestamps are not monotonic at event {index}: {previous_us} us followed by {t_us} us"
    )]
    NonMonotonic {
        /// Index of the first event whose timestamp is smaller than its predecessor's.
        index: usize,
        /// Timestamp of event `index - 1` (microseconds).
        previous_us: i64,
        /// Timestamp of event `index` (microseconds).
        t_us: i64,
    },
    /// An event lies outside the sensor.
    #[error("event {index} at (x={x}, y={y}) lies outside the {width}x{height} sensor")]
    OutsideSensor {
        /// Index of the offending event.
        index: usize,
        /// Its column (pixels).
        x: u16,
        /// Its row (pixels).
        y: u16,
        /// Sensor width (pixels).
        width: u32,
        /// Sensor height (pixels).
        height: u32,
    },
    /// An event's polarity is not +1 or -1.
    #[error("event {index} has polarity {p}, expected +1 or -1")]
    BadPolarity {
        /// Index of the offending event.
        index: usize,
        /// The stored polarity.
        p: i8,
    },
    /// A caller-supplied argument is out of its domain.
    #[error("invalid argument {name}: {message}")]
    InvalidArgument {
        /// Argument name.
        name: &'static str,
        /// What is wrong with its value.
        message: String,
    },
}

/// Result alias of the crate.
pub type Result<T> = std::result::Result<T, EventsError>;

impl EventsError {
    /// A [`EventsError::Format`] error for `path`.
    pub(crate) fn format(path: impl AsRef<Path>, message: impl Into<String>) -> Self {
        Self::Format {
            path: path.as_ref().display().to_string(),
            message: message.into(),
        }
    }

    /// A [`EventsError::Io`] error for `path`.
    pub(crate) fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.as_ref().display().to_string(),
            source,
        }
    }

    /// An [`EventsError::InvalidArgument`] error.
    pub(crate) fn arg(name: &'static str, message: impl Into<String>) -> Self {
        Self::InvalidArgument {
            name,
            message: message.into(),
        }
    }
}
