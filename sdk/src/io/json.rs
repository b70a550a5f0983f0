//! The SDK's JSON files read as a user would want their errors: the key path at fault (`samples[0].per_colour`,
//! through `serde_path_to_error`), the line and column, and the file format's own words where serde's would
//! mislead (an array with too many entries is not "trailing characters"; a document that is not an object does
//! not "expect a string"). Aberration files, spot plans and a display profile's nested objects share it.

use serde::de::DeserializeOwned;

/// Why a JSON document was refused: the key path (empty at the top level), the reason in the format's terms,
/// and where.
#[derive(Debug, Clone, PartialEq)]
pub struct JsonError {
    /// The key path at fault, serde_path_to_error's form (`samples[0].per_colour`); empty for the document.
    pub path: String,
    /// What is wrong, without the position.
    pub reason: String,
    /// 1-based line of the error (0 where the parser gives none).
    pub line: usize,
    /// 1-based column of the error (0 where the parser gives none).
    pub column: usize,
}

impl std::fmt::Display for JsonError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if !self.path.is_empty() {
            write!(f, "at `{}`: ", self.path)?;
        }
        write!(f, "{}", self.reason)?;
        if self.line > 0 {
            write!(f, " (line {}, column {})", self.line, self.column)?;
        }
        Ok(())
    }
}

/// What the first value of `text` is, in words (`an array`, `a string`, …), or `None` for an object.
fn kind_of(text: &str) -> Option<&'static str> {
    let text = text.trim_start();
    Some(match text.chars().next()? {
        '{' => return None,
        '[' => "an array",
        '"' => "a string",
        c if c == '-' || c.is_ascii_digit() => "a number",
        _ if text.starts_with("true") || text.starts_with("false") => "a boolean",
        _ if text.starts_with("null") => "null",
        _ => "text that is not JSON",
    })
}

/// Parses `text` (one JSON object, a UTF-8 byte-order mark allowed) as `T`. `what` names the object in the
/// refusal of another kind of value (`an aberration profile`, `the prescription`).
///
/// Errors: [`JsonError`] with the key path: not an object ("must be one JSON object"), text after it, an
/// array with more entries than `T` holds, and every error of `T`'s deserialisation (a missing, unknown or
/// repeated key, a value of the wrong type, an error of a `try_from` check) in serde's words.
pub(crate) fn parse_json_object<T: DeserializeOwned>(
    text: &str,
    what: &str,
) -> std::result::Result<T, JsonError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    if let Some(kind) = kind_of(text) {
        return Err(JsonError {
            path: String::new(),
            reason: format!("must be one JSON object {{…}} ({what}), got {kind}"),
            line: 0,
            column: 0,
        });
    }
    let refused = |path: String, inner: &serde_json::Error| {
        let msg = inner.to_string();
        let bare = msg
            .rsplit_once(" at line ")
            .map_or(msg.as_str(), |(m, _)| m)
            .to_string();
        let reason = if bare.starts_with("trailing characters") && !path.is_empty() {
            "more entries than it holds (an array of fixed length: e.g. `per_colour` and \
             `wavelengths_m` hold [R, G, B])"
                .to_string()
        } else if bare.starts_with("trailing characters") {
            format!("text after the closing brace of {what}: a file holds one")
        } else {
            bare
        };
        JsonError {
            path,
            reason,
            line: inner.line(),
            column: inner.column(),
        }
    };
    let mut de = serde_json::Deserializer::from_str(text);
    let value = serde_path_to_error::deserialize::<_, T>(&mut de).map_err(|e| {
        let path = e.path().to_string();
        refused(if path == "." { String::new() } else { path }, e.inner())
    })?;
    de.end().map_err(|e| refused(String::new(), &e))?;
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Inner {
        a: f64,
        #[serde(default)]
        rgb: Option<[f64; 3]>,
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Outer {
        items: Vec<Inner>,
    }

    fn err(text: &str) -> JsonError {
        parse_json_object::<Outer>(text, "a test file").unwrap_err()
    }

    #[test]
    fn errors_name_the_key_path_and_say_what_is_wrong_in_the_formats_terms() {
        let ok: Outer = parse_json_object("\u{feff}{\"items\": [{\"a\": 1}]}", "x").unwrap();
        assert_eq!(ok.items.len(), 1);
        let e = err("{\"items\": [{\"a\": 1}, {\"a\": 1, \"rgb\": [1, 2, 3, 4]}]}");
        assert_eq!(e.path, "items[1].rgb");
        assert!(e.reason.contains("more entries"), "{e}");
        let e = err("{\"items\": [{\"a\": \"one\"}]}");
        assert_eq!(e.path, "items[0].a");
        assert!(e.reason.contains("invalid type: string"), "{e}");
        assert_eq!((e.line, e.column > 0), (1, true));
        let e = err("{\"items\": [{\"a\": 1, \"a\": 2}]}");
        assert_eq!(e.path, "items[0]");
        assert!(e.reason.contains("duplicate field `a`"), "{e}");
        let e = err("{\"items\": [{\"b\": 1}]}");
        assert!(e.reason.contains("unknown field `b`"), "{e}");
        let e = err("[{\"items\": []}]");
        assert!(e.reason.contains("must be one JSON object") && e.reason.contains("an array"));
        let e = err("items: []");
        assert!(e.reason.contains("text that is not JSON"), "{e}");
        let e = err("{\"items\": []} {}");
        assert!(e.reason.contains("text after the closing brace"), "{e}");
        assert!(e.path.is_empty());
        assert_eq!(
            e.to_string(),
            format!("{} (line 1, column {})", e.reason, e.column)
        );
    }
}
