//! Text and numbers from a user as an error echoes them: escaped, short, bounded.

use core::fmt;

/// A number a user gave, as an error echoes it: as written for ordinary magnitudes, in
/// exponent form beyond them (`{}` printed -1e301 as 302 digits).
#[derive(Clone, Copy, Debug)]
pub struct ShownNumber(pub f64);

impl fmt::Display for ShownNumber {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let x = self.0;
        if x == 0.0 || !x.is_finite() || (1e-4..1e9).contains(&x.abs()) {
            write!(f, "{x}")
        } else {
            write!(f, "{x:e}")
        }
    }
}

/// Text a user gave, as an error echoes it: escaped (a newline, U+2028 or an ANSI escape
/// cannot split or restyle the one-line message) and cut to 40 characters.
pub struct Shown<'a>(pub &'a str);

impl fmt::Display for Shown<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const MAX: usize = 40;
        for (written, c) in self.0.chars().flat_map(char::escape_debug).enumerate() {
            if written == MAX {
                return f.write_str("…");
            }
            fmt::Write::write_char(f, c)?;
        }
        Ok(())
    }
}
