//! The crate's one error type.

use std::fmt;

/// Why a kernel call or a plan was refused. Every public function checks its input and returns one of these
/// instead of panicking.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum KernelError {
    /// A slice has the wrong number of elements.
    Length {
        /// What the slice is (e.g. "weights").
        what: &'static str,
        /// The number of elements the shapes require.
        expected: usize,
        /// The number of elements given.
        got: usize,
    },
    /// Two shapes that must agree do not (channels, height or width).
    Shape {
        /// What disagrees, in words.
        what: String,
    },
    /// A dimension is zero or too large.
    Dimension {
        /// What the dimension is.
        what: &'static str,
        /// Its value.
        value: usize,
    },
    /// The row band `[start, end)` is empty, reversed or past the frame height.
    Rows {
        /// First row of the band.
        start: usize,
        /// One past the last row of the band.
        end: usize,
        /// Frame height.
        height: usize,
    },
    /// A parameter (scale, kernel size…) is not usable: not finite, not positive, even…
    Parameter {
        /// Which parameter and why.
        what: String,
    },
    /// The ISA named (in `TENSORHOLO_ISA` or an explicit call) is unknown or not available on this CPU.
    Isa {
        /// The name asked for.
        name: String,
        /// Why it was refused.
        why: &'static str,
    },
    /// No kernel row of that name exists, or it cannot run on this CPU.
    Kernel {
        /// The name asked for.
        name: String,
    },
}

impl fmt::Display for KernelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Length {
                what,
                expected,
                got,
            } => {
                write!(f, "{what}: expected {expected} elements, got {got}")
            }
            Self::Shape { what } => write!(f, "shape mismatch: {what}"),
            Self::Dimension { what, value } => write!(f, "bad dimension {what} = {value}"),
            Self::Rows { start, end, height } => {
                write!(
                    f,
                    "row band {start}..{end} is not inside 0..{height} or is empty"
                )
            }
            Self::Parameter { what } => write!(f, "bad parameter: {what}"),
            Self::Isa { name, why } => write!(f, "ISA '{name}' refused: {why}"),
            Self::Kernel { name } => write!(f, "no kernel row '{name}' that runs on this CPU"),
        }
    }
}

impl std::error::Error for KernelError {}
