//! The local wall-clock time, as image headers carry it.

/// Now in local time as TIFF, EXIF and OpenEXR's `DateTime` write it: "2026:12:07 17:44:43".
pub fn local_date_time() -> String {
    // SAFETY: time with a null pointer only returns the time; localtime_r writes the struct it
    // is given and nothing else (it is the thread-safe form).
    let tm = unsafe {
        let now = libc::time(std::ptr::null_mut());
        let mut tm: libc::tm = std::mem::zeroed();
        if libc::localtime_r(&now, &mut tm).is_null() {
            return String::new();
        }
        tm
    };
    format!(
        "{:04}:{:02}:{:02} {:02}:{:02}:{:02}",
        tm.tm_year + 1900,
        tm.tm_mon + 1,
        tm.tm_mday,
        tm.tm_hour,
        tm.tm_min,
        tm.tm_sec
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn reads_as_a_date_and_a_time() {
        let text = super::local_date_time();
        let digits: Vec<u32> = text
            .split([':', ' '])
            .map(|part| part.parse().expect("a number"))
            .collect();
        assert_eq!(digits.len(), 6, "{text}");
        assert!(digits[0] >= 2024 && (1..=12).contains(&digits[1]) && (1..=31).contains(&digits[2]));
    }
}
