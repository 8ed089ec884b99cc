//! The JSON examples of the protocol documents, as the tests and the fuzzing harness
//! (`examples/fuzz.rs`, which includes this file) read them. Nothing here may use what only
//! integration tests have (such as `CARGO_BIN_EXE_*`).

/// Removes `//` comments outside strings, so a spec's annotated JSON parses.
pub fn strip_json_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        let mut in_string = false;
        let mut escaped = false;
        let mut cut = line.len();
        let bytes = line.as_bytes();
        for (i, &b) in bytes.iter().enumerate() {
            match b {
                _ if escaped => escaped = false,
                b'\\' if in_string => escaped = true,
                b'"' => in_string = !in_string,
                b'/' if !in_string && bytes.get(i + 1) == Some(&b'/') => {
                    cut = i;
                    break;
                }
                _ => {}
            }
        }
        out.push_str(&line[..cut]);
        out.push('\n');
    }
    out
}

/// Every ```json block of a Markdown spec, comments removed, with the heading above it.
pub fn markdown_json_examples(text: &str) -> Vec<(String, serde_json::Value)> {
    let mut out = Vec::new();
    let mut heading = String::new();
    let mut block: Option<String> = None;
    for line in text.lines() {
        let trimmed = line.trim();
        match &mut block {
            Some(b) if trimmed.starts_with("```") => {
                let json = strip_json_comments(b);
                let value = serde_json::from_str(&json).unwrap_or_else(|e| {
                    panic!("example under {heading:?} does not parse: {e}\n{json}")
                });
                out.push((heading.clone(), value));
                block = None;
            }
            Some(b) => {
                b.push_str(line);
                b.push('\n');
            }
            None if trimmed.starts_with("```json") => block = Some(String::new()),
            None if trimmed.starts_with('#') => {
                heading = trimmed.trim_start_matches('#').trim().to_owned()
            }
            None => {}
        }
    }
    out
}

/// A JSON example of a reStructuredText spec, with the topic named above it.
#[derive(Debug, Clone)]
pub struct RstExample {
    /// The last `Topic` line before it, `${vehicleId}` replaced.
    pub topic: String,
    /// The block as written.
    pub text: String,
}

/// Every `.. code-block:: json` of root-mqtt-api.rst with its topic (`${vehicleId}` →
/// `vehicle_id`).
pub fn rst_json_examples(text: &str, vehicle_id: &str) -> Vec<RstExample> {
    let mut out = Vec::new();
    let mut topic = String::new();
    let lines: Vec<&str> = text.lines().collect();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i].trim();
        if line.starts_with("/root/") {
            topic = line.replace("**", "").replace("${vehicleId}", vehicle_id);
        }
        if line.starts_with(".. code-block:: json") {
            let mut block = Vec::new();
            i += 1;
            // Blank lines, then the indented block.
            while i < lines.len() && lines[i].trim().is_empty() {
                i += 1;
            }
            let indent = lines.get(i).map_or(0, |l| l.len() - l.trim_start().len());
            while i < lines.len()
                && (lines[i].trim().is_empty()
                    || lines[i].len() - lines[i].trim_start().len() >= indent)
            {
                block.push(lines[i].trim_end());
                i += 1;
            }
            out.push(RstExample {
                topic: topic.clone(),
                text: block.join("\n").trim().to_owned(),
            });
            continue;
        }
        i += 1;
    }
    out
}
