//! The tokens of `nerve ui`: the edit token and the read token, asked of
//! every `/api/*` request; random unless given (from the environment or a
//! 0600 file, never the command line), and compared in constant time.

use std::io::Read;

/// A fresh token: 128 bits from the kernel's random source, as hex.
pub fn new_token() -> std::io::Result<String> {
    let mut bytes = [0u8; 16];
    std::fs::File::open("/dev/urandom")?.read_exact(&mut bytes)?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// Why a token given by the user is not usable, if it is not: at least 16
/// characters, and only `A-Z a-z 0-9 - . _ ~` (it goes in an address and a
/// cookie unchanged).
pub fn token_problem(token: &str) -> Option<&'static str> {
    if token.len() < 16 {
        return Some("it is shorter than 16 characters");
    }
    if token.len() > 256 {
        return Some("it is longer than 256 characters");
    }
    if !token.bytes().all(|b| b.is_ascii_alphanumeric() || b"-._~".contains(&b)) {
        return Some("it has characters other than A-Z, a-z, 0-9, '-', '.', '_' and '~'");
    }
    None
}

/// Compares a presented token with the real one in time that does not
/// depend on where they differ.
pub fn matches(presented: &str, token: &str) -> bool {
    let (a, b) = (presented.as_bytes(), token.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_are_random_hex_and_compared_exactly() {
        let (a, b) = (new_token().expect("urandom"), new_token().expect("urandom"));
        assert_eq!(a.len(), 32);
        assert!(a.chars().all(|c| c.is_ascii_hexdigit()));
        assert_ne!(a, b);
        assert!(matches(&a, &a));
        assert!(!matches(&b, &a));
        assert!(!matches("", &a));
        assert!(!matches(&a[..31], &a));
        assert_eq!(token_problem(&a), None);
        assert!(token_problem("short").is_some());
        assert!(token_problem("0123456789abcdef; x=1").is_some());
    }
}
