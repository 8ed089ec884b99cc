//! The caster's sourcetable: its `STR;` lines name the mountpoints, and field 12 (`nmea`)
//! says whether a mountpoint wants the rover's position as GGA (a virtual reference
//! station does).

/// One mountpoint of the table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stream {
    /// Its name.
    pub mountpoint: String,
    /// The data format (`RTCM 3.2`, ...).
    pub format: String,
    /// Whether it wants GGA from the rover.
    pub wants_gga: bool,
}

/// The most mountpoints kept: a caster's table is a claim, not a size.
pub const MAX_STREAMS: usize = 10_000;
/// The longest table read, bytes.
pub const MAX_TABLE: usize = 4 * 1024 * 1024;

/// Reads the `STR` lines of `text` (the rest, `CAS`, `NET`, `ENDSOURCETABLE`, is skipped).
pub fn parse(text: &str) -> Vec<Stream> {
    text.lines()
        .filter_map(|line| {
            let fields: Vec<&str> = line.trim_end_matches('\r').split(';').collect();
            if fields.first() != Some(&"STR") {
                return None;
            }
            let mountpoint = fields.get(1)?.trim();
            if mountpoint.is_empty() {
                return None;
            }
            Some(Stream {
                mountpoint: mountpoint.to_owned(),
                format: fields.get(3).map_or("", |f| f.trim()).to_owned(),
                wants_gga: fields.get(11).is_some_and(|f| f.trim() == "1"),
            })
        })
        .take(MAX_STREAMS)
        .collect()
}

/// Whether a table's text has ended (`ENDSOURCETABLE`).
pub fn is_complete(text: &str) -> bool {
    text.lines().any(|l| l.trim() == "ENDSOURCETABLE")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_and_odd_lines_are_skipped() {
        let t = "STR;\nSTR;A;x;RTCM 3.2;;;;;;;;0\r\nSTR;B\nCAS;h;2101\nENDSOURCETABLE\r\n";
        let s = parse(t);
        assert_eq!(s.len(), 2);
        assert!(!s[0].wants_gga && !s[1].wants_gga);
        assert_eq!(s[1].mountpoint, "B");
    }
}
