//! Where each key of a scene file is (its dotted path and line), and serde's messages rewritten
//! in the scene file's terms, so every error can name the key, its line and what is allowed.

use super::ROOT_REQUIRED;

/// Source positions of every key and value in a parsed document, by full dotted path
/// (`walls[1].motion.rpm`): turns serde's byte spans into key names, and key names into lines.
pub struct SpanIndex {
    entries: Vec<SpanEntry>,
    line_starts: Vec<usize>,
}

struct SpanEntry {
    path: String,
    key: std::ops::Range<usize>,
    value: std::ops::Range<usize>,
}

impl SpanIndex {
    /// Indexes `doc`, parsed from `text`.
    pub fn new(text: &str, doc: &toml::de::DeTable<'_>) -> Self {
        let mut entries = Vec::new();
        walk_table("", doc, &mut entries);
        let line_starts = std::iter::once(0)
            .chain(text.match_indices('\n').map(|(i, _)| i + 1))
            .collect();
        SpanIndex {
            entries,
            line_starts,
        }
    }

    /// 1-based (line, column) of byte offset `pos`.
    pub fn line_col(&self, text: &str, pos: usize) -> (usize, usize) {
        let line = self.line_starts.partition_point(|&s| s <= pos).max(1);
        let start = self.line_starts[line - 1];
        let col = text
            .get(start..pos.min(text.len()))
            .map_or(1, |s| s.chars().count() + 1);
        (line, col)
    }

    /// Every path in the file with the 1-based line of its key (kept by [`super::Scene`] so
    /// that errors found after validation, such as the domain decomposition's, name a line).
    pub fn key_lines(&self) -> Vec<(String, usize)> {
        self.entries
            .iter()
            .map(|e| {
                let line = self
                    .line_starts
                    .partition_point(|&s| s <= e.key.start)
                    .max(1);
                (e.path.clone(), line)
            })
            .collect()
    }

    /// Byte spans of the key and the value at exactly `path`.
    pub fn spans_of(&self, path: &str) -> Option<(std::ops::Range<usize>, std::ops::Range<usize>)> {
        self.entries
            .iter()
            .find(|e| e.path == path)
            .map(|e| (e.key.clone(), e.value.clone()))
    }

    /// 1-based line of `path`, or of its nearest ancestor that is in the file.
    pub fn line_of(&self, path: &str) -> Option<usize> {
        let mut p = path;
        loop {
            if let Some(e) = self.entries.iter().find(|e| e.path == p) {
                return Some(
                    self.line_starts
                        .partition_point(|&s| s <= e.key.start)
                        .max(1),
                );
            }
            // Strip the last `.key` or `[i]`.
            let cut = p.rfind(['.', '['])?;
            p = &p[..cut];
        }
    }

    /// The path whose key or value is at `span`: an exact key match, else an exact value match,
    /// else the smallest value containing it; the deepest path on ties.
    pub fn path_at(&self, span: &std::ops::Range<usize>) -> String {
        let deepest = |it: &mut dyn Iterator<Item = &SpanEntry>| {
            it.max_by_key(|e| e.path.len()).map(|e| e.path.clone())
        };
        if let Some(p) = deepest(&mut self.entries.iter().filter(|e| e.key == *span)) {
            return p;
        }
        if let Some(p) = deepest(&mut self.entries.iter().filter(|e| e.value == *span)) {
            return p;
        }
        self.entries
            .iter()
            .filter(|e| e.value.start <= span.start && span.end <= e.value.end)
            .min_by_key(|e| (e.value.end - e.value.start, usize::MAX - e.path.len()))
            .map(|e| e.path.clone())
            .unwrap_or_default()
    }
}

fn join(prefix: &str, key: &str) -> String {
    if prefix.is_empty() {
        key.to_string()
    } else {
        format!("{prefix}.{key}")
    }
}

fn walk_table(prefix: &str, table: &toml::de::DeTable<'_>, out: &mut Vec<SpanEntry>) {
    for (k, v) in table.iter() {
        let path = join(prefix, k.get_ref());
        out.push(SpanEntry {
            path: path.clone(),
            key: k.span(),
            value: v.span(),
        });
        walk_value(&path, v.get_ref(), out);
    }
}

fn walk_value(path: &str, v: &toml::de::DeValue<'_>, out: &mut Vec<SpanEntry>) {
    match v {
        toml::de::DeValue::Table(t) => walk_table(path, t, out),
        toml::de::DeValue::Array(a) => {
            for (i, e) in a.iter().enumerate() {
                let p = format!("{path}[{i}]");
                out.push(SpanEntry {
                    path: p.clone(),
                    key: e.span(),
                    value: e.span(),
                });
                walk_value(&p, e.get_ref(), out);
            }
        }
        _ => {}
    }
}
/// Rewrites a serde message about the key at `path` into (full key, message in scene terms).
pub fn explain_serde_message(path: &str, message: &str) -> (String, String) {
    let quoted = |rest: &str| rest.split('`').nth(1).unwrap_or("").to_string();
    let allowed = |rest: &str| {
        rest.split_once(", expected ")
            .map(|(_, e)| e.trim_start_matches("one of ").replace(" or ", ", "))
            .unwrap_or_default()
    };
    let full = |name: &str| {
        let last = path.rsplit(['.', '[']).next().unwrap_or("");
        if last == name {
            path.to_string()
        } else {
            join(path, name)
        }
    };
    if let Some(rest) = message.strip_prefix("unknown field ") {
        let name = quoted(rest);
        let key = full(&name);
        let mut msg = match allowed(rest) {
            a if a.is_empty() => "unknown key; this table takes no keys".to_string(),
            a => format!("unknown key; allowed keys: {a}"),
        };
        if rest.contains("`kind`") {
            msg.push_str(" (each kind takes only some of them; see docs/scene.md)");
        }
        if name == "gravity" && key != "gravity" {
            msg.push_str(" (gravity is a top-level key: write it before the first [section])");
        }
        return (key, msg);
    }
    if let Some(rest) = message.strip_prefix("missing field ") {
        let name = quoted(rest);
        // The document's span can equal its only section's, which would make a missing
        // section look like a key of that section (`simulation.domain`).
        if ROOT_REQUIRED.contains(&name.as_str()) {
            return (name.clone(), format!("missing required section [{name}]"));
        }
        return (full(&name), "missing required key".to_string());
    }
    if let Some(rest) = message.strip_prefix("unknown variant ") {
        return (
            path.to_string(),
            format!(
                "unknown value `{}`; allowed: {}",
                quoted(rest),
                allowed(rest)
            ),
        );
    }
    let msg = message
        .replace("expected f64", "expected a number")
        .replace("expected u64", "expected a non-negative integer")
        .replace("expected u32", "expected a non-negative integer below 2^32")
        .replace("expected usize", "expected a non-negative integer");
    (path.to_string(), msg)
}
