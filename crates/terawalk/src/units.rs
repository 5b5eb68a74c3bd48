//! Parsing and printing of human quantities: "2G" bytes, "100M" triangles, durations, rates.
//! Every size and rate the program prints goes through the `fmt_` functions here.

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

/// A byte size for messages, in binary units ("1.5 GiB", "12.4 MiB", "512 KiB", "100 B"),
/// three significant digits. Binary, because `--memory 2G` and the other size options are
/// binary (`parse_bytes`): one byte budget reads the same wherever the program prints it.
pub fn fmt_bytes(b: u64) -> String {
    const UNITS: [&str; 5] = ["KiB", "MiB", "GiB", "TiB", "PiB"];
    if b < 1024 {
        return format!("{b} B");
    }
    let mut value = b as f64 / 1024.0;
    let mut unit = 0;
    // Past 999.5 the three digits would round to 1000: the next unit says it as 0.98.
    while value >= 999.5 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    format!("{} {}", sig3(value), UNITS[unit])
}

/// A data rate for messages: [`fmt_bytes`] per second ("12.4 MiB/s").
pub fn fmt_byte_rate(bytes: u64, seconds: f64) -> String {
    let per_second = bytes as f64 / seconds.max(1e-9);
    format!("{}/s", fmt_bytes(per_second.min(u64::MAX as f64) as u64))
}

/// A count per second for messages, three significant digits with a decimal prefix ("0.79 M
/// triangles/s", "12.4 k triangles/s", "310 triangles/s"). A million and more says M (and G),
/// so that build and import speeds compare at a glance; less says k or nothing.
pub fn fmt_count_rate(count: u64, seconds: f64, what: &str) -> String {
    let per_second = count as f64 / seconds.max(1e-9);
    let (value, prefix) = match per_second {
        r if r >= 999.5e6 => (r / 1e9, "G "),
        r if r >= 1e5 => (r / 1e6, "M "),
        r if r >= 999.5 => (r / 1e3, "k "),
        r => (r, ""),
    };
    format!("{} {prefix}{what}/s", sig3(value))
}

/// `v` with three significant digits, trailing zeros of the fraction dropped: 0.79, 12.4, 512,
/// 1.5. Values of 1000 and more keep all their integer digits.
fn sig3(v: f64) -> String {
    if !v.is_finite() {
        return v.to_string();
    }
    let decimals = match v.abs() {
        0.0 => 0,
        a if a >= 99.95 => 0,
        a if a >= 9.995 => 1,
        a if a >= 0.9995 => 2,
        // 0.0123: two significant digits past the zeros, plus one.
        a => (2 - a.log10().floor() as i32).clamp(0, 9) as usize,
    };
    let text = format!("{v:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

/// "12,345,678" (`tw_core::digits::thousands`).
pub fn fmt_count(n: u64) -> String {
    tw_core::digits::thousands(n)
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
    }

    #[test]
    fn sizes_are_binary_with_three_significant_digits() {
        assert_eq!(fmt_bytes(100), "100 B");
        assert_eq!(fmt_bytes(512 << 10), "512 KiB");
        assert_eq!(fmt_bytes(3 << 29), "1.5 GiB");
        assert_eq!(fmt_bytes(13_002_342), "12.4 MiB");
        assert_eq!(fmt_bytes(2 << 30), "2 GiB");
        // Just below a unit: 1023.9 KiB is 1 MiB, not "1024 KiB".
        assert_eq!(fmt_bytes((1 << 20) - 100), "1 MiB");
        assert_eq!(fmt_bytes(u64::MAX), "16384 PiB");
        // The budget a user typed prints as typed.
        assert_eq!(fmt_bytes(parse_bytes("512M").unwrap()), "512 MiB");
    }

    #[test]
    fn rates_have_three_significant_digits() {
        assert_eq!(fmt_count_rate(790_000, 1.0, "triangles"), "0.79 M triangles/s");
        assert_eq!(fmt_count_rate(1_234_567, 1.0, "triangles"), "1.23 M triangles/s");
        assert_eq!(fmt_count_rate(12_345, 1.0, "triangles"), "12.3 k triangles/s");
        assert_eq!(fmt_count_rate(310, 1.0, "triangles"), "310 triangles/s");
        assert_eq!(fmt_count_rate(5, 4.0, "triangles"), "1.25 triangles/s");
        assert_eq!(fmt_count_rate(2_500_000_000, 1.0, "triangles"), "2.5 G triangles/s");
        assert_eq!(fmt_count_rate(0, 0.0, "triangles"), "0 triangles/s");
        assert_eq!(fmt_byte_rate(13_002_342, 1.0), "12.4 MiB/s");
        assert_eq!(sig3(0.012345), "0.0123");
    }
}
