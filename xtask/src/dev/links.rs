//! Relative links of the documentation: `README.md` and every `docs/*.md`.
//!
//! Every Markdown link and image, `[text](target)` and `![alt](target)` (and reference
//! definitions, `[label]: target`), outside fenced code blocks and inline code, must
//! resolve: its file (or folder) exists, relative to the linking file's folder (a target
//! starting with `/` from the repository's root), and for `file.md#anchor` the file has a
//! heading with that GitHub-style slug; a pure `#anchor`, the linking file's own headings.
//! Links to `http:`, `https:` and `mailto:` are not checked. Standard library only.

use std::collections::HashSet;
use std::path::{Component, Path, PathBuf};

/// Checks the relative links of `root`'s `README.md` and `docs/*.md`. Returns the number of
/// links checked, or one line per broken link, `FILE:LINE: TARGET (why)`, with `FILE`
/// relative to `root`.
pub fn check_links(root: &Path) -> Result<usize, String> {
    let mut files = vec![root.join("README.md")];
    let docs = root.join("docs");
    if docs.is_dir() {
        let entries = std::fs::read_dir(&docs).map_err(|e| format!("{}: {e}", docs.display()))?;
        let mut md: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file() && p.extension().is_some_and(|x| x == "md"))
            .collect();
        md.sort();
        files.extend(md);
    }
    let mut checked = 0;
    let mut broken = Vec::new();
    for file in &files {
        let shown = display(root, file);
        let text = std::fs::read_to_string(file).map_err(|e| format!("{shown}: {e}"))?;
        for link in links(&text) {
            if is_external(&link.target) {
                continue;
            }
            checked += 1;
            if let Err(why) = check_one(root, file, &link.target) {
                broken.push(format!("{shown}:{}: {} ({why})", link.line, link.target));
            }
        }
    }
    if broken.is_empty() {
        Ok(checked)
    } else {
        Err(broken.join("\n"))
    }
}

/// A link's target and the line (from 1) it is on.
#[derive(Debug, PartialEq)]
struct Link {
    line: usize,
    target: String,
}

fn is_external(target: &str) -> bool {
    let lower = target.to_ascii_lowercase();
    ["http:", "https:", "mailto:"]
        .iter()
        .any(|scheme| lower.starts_with(scheme))
}

/// `path` relative to `root` with `/` separators, for messages.
fn display(root: &Path, path: &Path) -> String {
    let rel = path.strip_prefix(root).unwrap_or(path);
    let parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    parts.join("/")
}

/// Resolves one relative target from the linking file; why it is broken otherwise.
fn check_one(root: &Path, from: &Path, target: &str) -> Result<(), String> {
    let (path, anchor) = match target.split_once('#') {
        Some((p, a)) => (p, Some(a)),
        None => (target, None),
    };
    let path = percent_decode(path);
    let base = if path.starts_with('/') {
        root.to_path_buf()
    } else {
        from.parent().unwrap_or(root).to_path_buf()
    };
    // `#anchor` alone: a heading of the linking file itself.
    let resolved = if path.is_empty() {
        from.to_path_buf()
    } else {
        normalize(&base.join(path.trim_start_matches('/')))
    };
    if !resolved.starts_with(normalize(root)) {
        return Err("outside the repository".into());
    }
    if !resolved.exists() {
        return Err("no such file".into());
    }
    let Some(anchor) = anchor.filter(|a| !a.is_empty()) else {
        return Ok(());
    };
    let is_markdown = resolved
        .extension()
        .is_some_and(|x| x.eq_ignore_ascii_case("md"));
    if !is_markdown || !resolved.is_file() {
        return Ok(());
    }
    let text = std::fs::read_to_string(&resolved)
        .map_err(|e| format!("cannot read {}: {e}", display(root, &resolved)))?;
    let anchor = percent_decode(anchor).to_lowercase();
    if heading_slugs(&text).contains(&anchor) {
        Ok(())
    } else {
        Err(format!(
            "no heading with the anchor #{anchor} in {}",
            display(root, &resolved)
        ))
    }
}

/// `a/./b/../c` → `a/c`, without touching the file system.
fn normalize(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

/// `%20` and the like, as a browser reads a URL's path.
fn percent_decode(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            let hex = std::str::from_utf8(&bytes[i + 1..i + 3]).ok();
            if let Some(b) = hex.and_then(|h| u8::from_str_radix(h, 16).ok()) {
                out.push(b);
                i += 3;
                continue;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The lines of `text` outside fenced code blocks, with their numbers (from 1).
fn prose_lines(text: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    // The open fence: its character and length (a closing fence is at least as long).
    let mut fence: Option<(char, usize)> = None;
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        let indent = line.len() - trimmed.len();
        let marker = trimmed.chars().next().filter(|c| *c == '`' || *c == '~');
        let run = marker.map_or(0, |m| trimmed.chars().take_while(|c| *c == m).count());
        match fence {
            Some((c, n)) => {
                if marker == Some(c) && run >= n && trimmed[run..].trim().is_empty() {
                    fence = None;
                }
            }
            None => {
                // An info string after backticks may not contain a backtick.
                let info = marker.map(|_| &trimmed[run..]);
                let opens = run >= 3
                    && indent <= 3
                    && !(marker == Some('`') && info.is_some_and(|s| s.contains('`')));
                if opens {
                    fence = marker.map(|m| (m, run));
                } else {
                    out.push((i + 1, line));
                }
            }
        }
    }
    out
}

/// `line` with every inline code span blanked out, so that its text is not read as links.
fn without_code_spans(line: &str) -> String {
    let chars: Vec<char> = line.chars().collect();
    let mut out = String::with_capacity(line.len());
    let mut i = 0;
    while i < chars.len() {
        if chars[i] != '`' {
            out.push(chars[i]);
            i += 1;
            continue;
        }
        let open = chars[i..].iter().take_while(|c| **c == '`').count();
        // The closing run of exactly as many backticks.
        let mut j = i + open;
        let mut close = None;
        while j < chars.len() {
            if chars[j] == '`' {
                let run = chars[j..].iter().take_while(|c| **c == '`').count();
                if run == open {
                    close = Some(j);
                    break;
                }
                j += run;
            } else {
                j += 1;
            }
        }
        match close {
            Some(j) => {
                out.extend(std::iter::repeat_n(' ', j + open - i));
                i = j + open;
            }
            None => {
                // No closing run: the backticks are literal.
                out.extend(std::iter::repeat_n('`', open));
                i += open;
            }
        }
    }
    out
}

/// Every link and image target of `text` outside code.
fn links(text: &str) -> Vec<Link> {
    let mut out = Vec::new();
    for (line_no, line) in prose_lines(text) {
        let line = without_code_spans(line);
        // A reference definition: `[label]: target`.
        let trimmed = line.trim_start();
        if trimmed.starts_with('[') && !trimmed.starts_with("[^") {
            if let Some(end) = trimmed.find("]:") {
                let target = trimmed[end + 2..].split_whitespace().next().unwrap_or("");
                let target = target.trim_start_matches('<').trim_end_matches('>');
                if !target.is_empty() {
                    out.push(Link {
                        line: line_no,
                        target: target.to_string(),
                    });
                }
                continue;
            }
        }
        let chars: Vec<char> = line.chars().collect();
        let mut i = 0;
        while i + 1 < chars.len() {
            if chars[i] != ']' || chars[i + 1] != '(' || !chars[..i].contains(&'[') {
                i += 1;
                continue;
            }
            // The target runs to the matching `)`; parentheses inside it must balance.
            let mut depth = 0usize;
            let mut j = i + 2;
            let mut end = None;
            while j < chars.len() {
                match chars[j] {
                    '(' => depth += 1,
                    ')' if depth == 0 => {
                        end = Some(j);
                        break;
                    }
                    ')' => depth -= 1,
                    _ => {}
                }
                j += 1;
            }
            let Some(end) = end else { break };
            let inside: String = chars[i + 2..end].iter().collect();
            let inside = inside.trim();
            // `<target with spaces>` or `target "title"`.
            let target = if let Some(rest) = inside.strip_prefix('<') {
                rest.split('>').next().unwrap_or("")
            } else {
                inside.split_whitespace().next().unwrap_or("")
            };
            if !target.is_empty() {
                out.push(Link {
                    line: line_no,
                    target: target.to_string(),
                });
            }
            i = end + 1;
        }
    }
    out
}

/// The anchors GitHub gives the headings of `text` (ATX `# …` and setext, outside code),
/// a repeated one suffixed `-1`, `-2`, ….
fn heading_slugs(text: &str) -> HashSet<String> {
    let mut slugs = HashSet::new();
    let mut seen = std::collections::HashMap::<String, usize>::new();
    let mut add = |heading: &str| {
        let base = slug(heading);
        let n = seen.entry(base.clone()).or_insert(0);
        let slug = if *n == 0 {
            base.clone()
        } else {
            format!("{base}-{n}")
        };
        *n += 1;
        slugs.insert(slug);
    };
    let lines = prose_lines(text);
    for (k, &(no, line)) in lines.iter().enumerate() {
        let trimmed = line.trim_start();
        if line.len() - trimmed.len() <= 3 && trimmed.starts_with('#') {
            let hashes = trimmed.chars().take_while(|c| *c == '#').count();
            let rest = &trimmed[hashes..];
            if hashes <= 6 && (rest.is_empty() || rest.starts_with([' ', '\t'])) {
                // A closing run of `#`s is not part of the heading.
                let rest = rest.trim();
                let rest = rest.trim_end_matches('#');
                add(rest.trim_end());
                continue;
            }
        }
        // Setext: a text line underlined by `===` or `---` on the very next line.
        if let Some(&(next_no, next)) = lines.get(k + 1) {
            let under = next.trim();
            let underline = !under.is_empty()
                && (under.chars().all(|c| c == '=') || under.chars().all(|c| c == '-'));
            let text_line = !trimmed.is_empty()
                && !trimmed.starts_with(['#', '|', '-', '*', '>'])
                && !trimmed.starts_with(|c: char| c.is_ascii_digit());
            if next_no == no + 1 && underline && text_line {
                add(trimmed.trim_end());
            }
        }
    }
    slugs
}

/// GitHub's anchor of a heading: its text (links reduced to their text, code and emphasis
/// marks dropped) lowercased, every character but letters, digits, `_`, `-` and spaces
/// removed, and spaces made `-`.
fn slug(heading: &str) -> String {
    // `[text](target)` → `text`: the target is not part of the rendered heading.
    let mut plain = String::new();
    let chars: Vec<char> = heading.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        if chars[i] == ']' && chars.get(i + 1) == Some(&'(') {
            if let Some(close) = chars[i + 2..].iter().position(|c| *c == ')') {
                i += close + 3;
                continue;
            }
        }
        plain.push(chars[i]);
        i += 1;
    }
    plain
        .trim()
        .chars()
        .flat_map(char::to_lowercase)
        .filter_map(|c| match c {
            ' ' => Some('-'),
            '-' | '_' => Some(c),
            c if c.is_alphanumeric() => Some(c),
            _ => None,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// A fresh folder under the system's temporary folder, removed when dropped.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new() -> TempDir {
            static COUNT: AtomicUsize = AtomicUsize::new(0);
            let nanos = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.subsec_nanos());
            let dir = std::env::temp_dir().join(format!(
                "links-test-{}-{}-{nanos}",
                std::process::id(),
                COUNT.fetch_add(1, Ordering::Relaxed)
            ));
            std::fs::create_dir_all(dir.join("docs")).unwrap();
            TempDir(dir)
        }

        fn write(&self, name: &str, text: &str) {
            let path = self.0.join(name);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, text).unwrap();
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    #[test]
    fn good_links_resolve_and_are_counted() {
        let dir = TempDir::new();
        dir.write(
            "README.md",
            "# Title\n\nSee [the API](docs/api.md), [its part](docs/api.md#the-part-two), \
             ![a picture](img/shot.png \"title\") and [a folder](img/).\n\
             [External](https://example.com) and [mail](mailto:a@b.c), [here](#title).\n",
        );
        dir.write(
            "docs/api.md",
            "# API\n\n## The part: two\n\nBack to the [README](../README.md#title) and \
             [ref].\n\n[ref]: ./api.md#api\n",
        );
        dir.write("img/shot.png", "png");
        // README: the file, its anchor, the image, the folder, its own heading;
        // docs/api.md: two.
        assert_eq!(check_links(&dir.0), Ok(7));
    }

    #[test]
    fn a_missing_file_is_reported_with_its_line() {
        let dir = TempDir::new();
        dir.write(
            "README.md",
            "# Title\n\nok [a](docs/a.md)\n[b](docs/missing.md)\n",
        );
        dir.write("docs/a.md", "# A\n\n![gone](../gone.png)\n");
        let err = check_links(&dir.0).unwrap_err();
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(
            lines,
            [
                "README.md:4: docs/missing.md (no such file)",
                "docs/a.md:3: ../gone.png (no such file)",
            ],
            "{err}"
        );
    }

    #[test]
    fn a_bad_anchor_is_reported_and_a_good_one_is_not() {
        let dir = TempDir::new();
        dir.write(
            "README.md",
            "[good](docs/a.md#eval---json) [dup](docs/a.md#same-1)\n\
             [bad](docs/a.md#no-such-heading)\n[not markdown](x.txt#anything) [own](#nowhere)\n",
        );
        dir.write(
            "docs/a.md",
            "# A\n\n## `eval --json`\n\n## Same\n\n## Same\n",
        );
        dir.write("x.txt", "text");
        let err = check_links(&dir.0).unwrap_err();
        assert_eq!(
            err,
            "README.md:2: docs/a.md#no-such-heading (no heading with the anchor \
             #no-such-heading in docs/a.md)\n\
             README.md:3: #nowhere (no heading with the anchor #nowhere in README.md)"
        );
    }

    #[test]
    fn links_in_code_are_ignored() {
        let dir = TempDir::new();
        dir.write(
            "README.md",
            "```md\n[in a fence](missing.md)\n```\n\n~~~~\n```\n[still in](missing.md)\n~~~~\n\n\
             Inline `[code](missing.md)` too, and ``a `[b](missing.md)` c``.\n\n\
             [after the fences](docs/a.md)\n",
        );
        dir.write("docs/a.md", "# A\n\n```\n# not a heading\n```\n");
        assert_eq!(check_links(&dir.0), Ok(1));
        // A heading inside a fence is no anchor.
        dir.write("README.md", "[x](docs/a.md#not-a-heading)\n");
        assert!(check_links(&dir.0).unwrap_err().contains("no heading"));
    }

    #[test]
    fn a_missing_readme_is_an_error() {
        let dir = TempDir::new();
        assert!(check_links(&dir.0).unwrap_err().starts_with("README.md: "));
    }

    #[test]
    fn targets_are_read_as_markdown_does() {
        let found = links("a [x](<with space.md>) [y](f(1).md) ![z](p.png \"t\") [w]\n");
        let targets: Vec<&str> = found.iter().map(|l| l.target.as_str()).collect();
        assert_eq!(targets, ["with space.md", "f(1).md", "p.png"]);
        assert_eq!(percent_decode("a%20b%2"), "a b%2");
        assert_eq!(
            normalize(Path::new("/r/docs/../README.md")),
            Path::new("/r/README.md")
        );
    }

    #[test]
    fn slugs_follow_github() {
        assert_eq!(
            slug("Speed, beside CasADi's C and Pinocchio"),
            "speed-beside-casadis-c-and-pinocchio"
        );
        assert_eq!(slug("`eval --json`"), "eval---json");
        assert_eq!(
            slug("A leg in your own crate (on the robot)"),
            "a-leg-in-your-own-crate-on-the-robot"
        );
        assert_eq!(slug("See [the docs](docs/x.md) now"), "see-the-docs-now");
        assert_eq!(slug("Λ and snake_case"), "λ-and-snake_case");
        let slugs = heading_slugs("# Top #\n\nSetext\n======\n\n## Top\n\n| a |\n|---|\n");
        let mut slugs: Vec<String> = slugs.into_iter().collect();
        slugs.sort();
        assert_eq!(slugs, ["setext", "top", "top-1"]);
    }
}
