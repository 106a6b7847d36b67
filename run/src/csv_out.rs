//! Number formats of the simulator's CSV files, as serde values for the
//! `csv` crate.
//!
//! The crate writes `f64` in its shortest round-trip form (`12.0`, `1e-7`);
//! the files' contract is older: the trajectory has fixed decimals per
//! column, the sweep Rust's `Display` (`12`, `0.0000001`). These wrappers
//! keep those bytes while the crate does the records, quoting and
//! terminators.

use serde::{Serialize, Serializer};

/// `f64` written with `DIGITS` decimals (`{:.DIGITS$}`).
#[derive(Clone, Copy, Debug)]
pub struct Fixed<const DIGITS: usize>(pub f64);

impl<const DIGITS: usize> Serialize for Fixed<DIGITS> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(&format_args!("{:.*}", DIGITS, self.0))
    }
}

/// `f64` written as `Display` shows it (`{}`).
#[derive(Clone, Copy, Debug)]
pub struct Shown(pub f64);

impl Serialize for Shown {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(&self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record<T: Serialize>(row: T) -> String {
        let mut w = csv::WriterBuilder::new()
            .has_headers(false)
            .from_writer(Vec::new());
        w.serialize(row).unwrap();
        String::from_utf8(w.into_inner().unwrap()).unwrap()
    }

    #[test]
    fn formats_match_the_format_macros() {
        for v in [
            0.0,
            -0.0,
            12.0,
            1e-7,
            0.1 + 0.2,
            -3.5e20,
            f64::NAN,
            f64::INFINITY,
        ] {
            assert_eq!(
                record((Fixed::<6>(v), Fixed::<9>(v))),
                format!("{v:.6},{v:.9}\n")
            );
            assert_eq!(record((Shown(v), None::<Shown>)), format!("{v},\n"));
        }
    }
}
