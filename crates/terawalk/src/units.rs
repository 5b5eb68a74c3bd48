//! Parsing and printing of human quantities: "2G" bytes, "100M" triangles, durations, rates.

/// Parses a byte size: "512M", "2G", "1.5GiB", "4096" (binary units: K = 1024).
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let lower = t.to_ascii_lowercase();
    let digits_end =
        lower.find(|c: char| !(c.is_ascii_digit() || c == '.' || c == '_')).unwrap_or(lower.len());
    let (num, unit) = lower.split_at(digits_end);
    let value: f64 =
        num.replace('_', "").parse().map_err(|_| format!("not a size: {s:?} (try 512M or 2G)"))?;
    let mult: u64 = match unit.trim() {
        "" | "b" => 1,
        "k" | "kb" | "kib" => 1 << 10,
        "m" | "mb" | "mib" => 1 << 20,
        "g" | "gb" | "gib" => 1 << 30,
        "t" | "tb" | "tib" => 1 << 40,
        u => return Err(format!("unknown size unit {u:?} in {s:?} (use K, M, G or T)")),
    };
    let bytes = value * mult as f64;
    // 2^64 itself rounds to `u64::MAX as f64`: compare against the first value out of range.
    if !(0.0..18_446_744_073_709_551_616.0).contains(&bytes) {
        return Err(format!("size out of range: {s:?}"));
    }
    Ok(bytes as u64)
}

/// Parses the page cache's budget (`render`, `bench`, `view` `--memory`): a byte size of at
/// least 1 MiB. Less holds no page beside the root pages, and the frames would draw the
/// coarsest levels only while looking like an answer.
pub fn parse_page_budget(s: &str) -> Result<u64, String> {
    let bytes = parse_bytes(s)?;
    if bytes < 1 << 20 {
        return Err(format!("the page cache needs at least 1M, got {s:?}"));
    }
    Ok(bytes)
}

/// Parses a count: "100M", "2.5k", "1e8", "10^9", "1_000_000" (decimal units: k = 1000).
pub fn parse_count(s: &str) -> Result<u64, String> {
    let t = s.trim().replace('_', "");
    let err = || format!("not a count: {s:?} (try 1000000, 1M, 1e6 or 10^6)");
    if let Some((b, e)) = t.split_once('^') {
        let b: u64 = b.parse().map_err(|_| err())?;
        let e: u32 = e.parse().map_err(|_| err())?;
        return b.checked_pow(e).ok_or_else(err);
    }
    let (num, mult) = match t.chars().last() {
        Some('k' | 'K') => (&t[..t.len() - 1], 1e3),
        Some('m' | 'M') => (&t[..t.len() - 1], 1e6),
        Some('g' | 'G' | 'b' | 'B') => (&t[..t.len() - 1], 1e9),
        _ => (&t[..], 1.0),
    };
    let v: f64 = num.parse().map_err(|_| err())?;
    let v = v * mult;
    if !v.is_finite() || !(0.0..=1e18).contains(&v) || v.fract() != 0.0 {
        return Err(err());
    }
    Ok(v as u64)
}

/// "1.23 GB"-style decimal size for messages.
pub fn fmt_bytes(b: u64) -> String {
    let b = b as f64;
    if b >= 1e9 {
        format!("{:.2} GB", b / 1e9)
    } else if b >= 1e6 {
        format!("{:.1} MB", b / 1e6)
    } else if b >= 1e3 {
        format!("{:.1} kB", b / 1e3)
    } else {
        format!("{b} B")
    }
}

/// "12,345,678".
pub fn fmt_count(n: u64) -> String {
    let s = n.to_string();
    let mut out = String::with_capacity(s.len() + s.len() / 3);
    for (i, c) in s.chars().enumerate() {
        if i > 0 && (s.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_sizes() {
        assert_eq!(parse_bytes("512M"), Ok(512 << 20));
        assert_eq!(parse_bytes("2G"), Ok(2 << 30));
        assert_eq!(parse_bytes("1.5GiB"), Ok(3 << 29));
        assert_eq!(parse_bytes("4096"), Ok(4096));
        assert!(parse_bytes("lots").is_err());
        assert!(parse_bytes("3X").is_err());
        // 2^64 bytes and beyond are out of range, not clamped to u64::MAX.
        assert!(parse_bytes("18446744073709551616").is_err());
        assert!(parse_page_budget("0").is_err() && parse_page_budget("1000K").is_err());
        assert_eq!(parse_page_budget("1M"), Ok(1 << 20));
        assert!(parse_bytes("16777216T").is_err());
        assert_eq!(parse_bytes("18446744073709549568"), Ok(18446744073709549568));
    }

    #[test]
    fn counts() {
        assert_eq!(parse_count("100M"), Ok(100_000_000));
        assert_eq!(parse_count("2.5k"), Ok(2500));
        assert_eq!(parse_count("1e8"), Ok(100_000_000));
        assert_eq!(parse_count("10^9"), Ok(1_000_000_000));
        assert_eq!(parse_count("1_000"), Ok(1000));
        assert!(parse_count("1.5").is_err());
        assert!(parse_count("-3").is_err());
        assert!(parse_count("10^99").is_err());
    }

    #[test]
    fn formatting() {
        assert_eq!(fmt_count(1234567), "1,234,567");
        assert_eq!(fmt_count(12), "12");
        assert_eq!(fmt_bytes(1_500_000), "1.5 MB");
    }
}
