//! Where a study file's problems are: the line of a problem's dotted key path
//! (`session.subject_fields[2]`, `staircase.tracks[1].clip`) in the file's text, found
//! through the spans the TOML parser keeps (`[a.b]` headers, `[[a]]` arrays of tables, inline
//! tables and dotted keys alike).

use toml::Spanned;
use toml::de::{DeTable, DeValue};

use super::StudyIssue;
use super::line_col;

/// One step of a key path: a table's key or an array's element.
#[derive(Debug, PartialEq, Eq)]
enum Step<'a> {
    Key(&'a str),
    Index(usize),
}

/// The steps of `path` (`a.b[2].c` → `a`, `b`, `[2]`, `c`); `None` for a path that is not
/// one (an empty part, an index that is not a number).
fn steps(path: &str) -> Option<Vec<Step<'_>>> {
    let mut out = Vec::new();
    for part in path.split('.') {
        let (name, mut rest) = part.split_once('[').map_or((part, ""), |(n, r)| (n, r));
        if name.is_empty() {
            return None;
        }
        out.push(Step::Key(name));
        while !rest.is_empty() {
            let (index, after) = rest.split_once(']')?;
            out.push(Step::Index(index.parse().ok()?));
            rest = match after {
                "" => "",
                a => a.strip_prefix('[')?,
            };
        }
    }
    Some(out)
}

/// The byte offset where `path` is written in `table`: the key itself, or an array's
/// element; for a path the file does not hold (a missing key) the deepest table of its path
/// that it does hold, or `None` when that is the top level.
fn offset(table: &DeTable<'_>, path: &str) -> Option<usize> {
    let mut at = None;
    let mut value: Option<&DeValue<'_>> = None;
    for step in steps(path)? {
        let found: Option<(usize, &Spanned<DeValue<'_>>)> = match (step, value) {
            (Step::Key(k), None) => table.get_key_value(k).map(|(k, v)| (k.span().start, v)),
            (Step::Key(k), Some(DeValue::Table(t))) => {
                t.get_key_value(k).map(|(k, v)| (k.span().start, v))
            }
            (Step::Index(i), Some(DeValue::Array(a))) => a.get(i).map(|v| (v.span().start, v)),
            _ => None,
        };
        let Some((start, v)) = found else { break };
        at = Some(start);
        value = Some(v.get_ref());
    }
    at
}

/// Gives each of `issues` the line of its key in `text` (the study file the issues are
/// about); an issue whose key the file does not place keeps no line.
pub(super) fn locate(issues: &mut [StudyIssue], text: &str) {
    let Ok(table) = DeTable::parse(text) else {
        return;
    };
    for issue in issues.iter_mut().filter(|i| i.line.is_none()) {
        issue.line = offset(table.get_ref(), &issue.key).map(|at| line_col(text, at).0);
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn line(text: &str, path: &str) -> Option<usize> {
        let table = DeTable::parse(text).unwrap();
        offset(table.get_ref(), path).map(|at| line_col(text, at).0)
    }

    #[test]
    fn paths_split_into_keys_and_indices() {
        use Step::{Index, Key};
        assert_eq!(
            steps("a.b[2][3].c").unwrap(),
            vec![Key("a"), Key("b"), Index(2), Index(3), Key("c")]
        );
        assert_eq!(steps("a").unwrap(), vec![Key("a")]);
        assert!(steps("").is_none());
        assert!(steps("a..b").is_none());
        assert!(steps("a[x]").is_none());
        assert!(steps("a[1]b").is_none());
    }

    #[test]
    fn keys_are_found_in_headers_inline_tables_dotted_keys_and_arrays_of_tables() {
        let text = "name = \"s\"\nnmae = 1\n\n[session]\n# a comment\nsubject_fields = [\n  \"age\",\n  \
                    \"sex\",\n  \"hand\",\n]\n\n[[design.groups]]\nname = \"a\"\n\n[[design.groups]]\n\
                    name = \"b\"\ncolour = 3\n\n[staircase]\ntracks = [{ clip = \"walk\" }, { clip = \"run\" }]\n\
                    quest.colour = 2\n[scene.camera]\nzoom = 1\n";
        assert_eq!(line(text, "nmae"), Some(2));
        assert_eq!(line(text, "session"), Some(4));
        assert_eq!(line(text, "session.subject_fields"), Some(6));
        assert_eq!(line(text, "session.subject_fields[2]"), Some(9));
        assert_eq!(line(text, "design.groups[1]"), Some(15));
        assert_eq!(line(text, "design.groups[1].colour"), Some(17));
        assert_eq!(line(text, "design.groups[0].name"), Some(13));
        assert_eq!(line(text, "staircase.tracks[1].clip"), Some(20));
        assert_eq!(line(text, "staircase.quest.colour"), Some(21));
        assert_eq!(line(text, "scene.camera.zoom"), Some(23));
        // A key the file lacks: the table it belongs in; at the top level, no line.
        assert_eq!(line(text, "session.consent"), Some(4));
        assert_eq!(line(text, "design.groups[5].name"), Some(12));
        assert_eq!(line(text, "protocol"), None);
        assert_eq!(line(text, ""), None);
        // A path through a value that is not a table stops at that value.
        assert_eq!(line(text, "name.first"), Some(1));
    }
}
