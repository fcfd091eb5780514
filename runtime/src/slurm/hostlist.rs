//! SLURM's compressed host lists (`n[001-004,7],login1`), expanded by us rather than by calling
//! `scontrol show hostnames`: a task must not depend on SLURM's tools being on its `PATH`, and
//! a pure function can be tested on every form without a cluster.
//!
//! The grammar, as SLURM writes it: a list is expressions separated by commas outside brackets;
//! an expression is text and bracket groups in any order (`rack-1-n[01-04]`, `r[1-2]n[1-2]`); a
//! group is numbers and ranges `lo-hi` separated by commas. A range keeps the width of its low
//! end, so `[001-010]` gives `001` .. `010` and `[8-11]` gives `8` .. `11`. Several groups in one
//! expression expand as a cartesian product with the first group outermost (`r1n1, r1n2, r2n1,
//! r2n2`), as SLURM's own hostlist does. Hosts come out in the order written, never sorted or
//! deduplicated: order is what the caller's "first node" means.

/// The most hosts a list may expand to: far above any cluster, low enough that `n[0-999999999]`
/// is refused instead of filling memory.
pub const MAX_HOSTS: usize = 1 << 20;

/// Why a host list does not parse. Positions are byte offsets into the list, from 0.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HostlistError {
    /// No host at all.
    #[error("the host list is empty")]
    Empty,
    /// A host name with no characters.
    #[error("an empty host name at offset {at} (two commas, or a comma at an end)")]
    EmptyName {
        /// Where, in bytes from the list's start.
        at: usize,
    },
    /// A bracket group that never ends.
    #[error("`[` at offset {at} is never closed")]
    Unclosed {
        /// Where it opens, in bytes from the list's start.
        at: usize,
    },
    /// A closing bracket with no group open.
    #[error("`]` at offset {at} closes no `[`")]
    Unopened {
        /// Where, in bytes from the list's start.
        at: usize,
    },
    /// A bracket group opened inside another, which SLURM never writes.
    #[error("`[` at offset {at} inside another bracket group")]
    Nested {
        /// Where, in bytes from the list's start.
        at: usize,
    },
    /// A character no host name has.
    #[error("{found:?} at offset {at} cannot be part of a host name")]
    BadCharacter {
        /// The character.
        found: char,
        /// Where, in bytes from the list's start.
        at: usize,
    },
    /// Nothing between two commas of a bracket group.
    #[error("an empty entry in the bracket group at offset {at}")]
    EmptyRange {
        /// Where the group opens, in bytes from the list's start.
        at: usize,
    },
    /// An entry of a bracket group that is neither a number nor a range.
    #[error("{text:?} in the bracket group at offset {at} is not a number or a range lo-hi")]
    BadNumber {
        /// The entry.
        text: String,
        /// Where the group opens, in bytes from the list's start.
        at: usize,
    },
    /// A range whose end is below its start.
    #[error("the range {lo}-{hi} in the bracket group at offset {at} runs backwards")]
    Backwards {
        /// The range's start, as written.
        lo: String,
        /// The range's end, as written.
        hi: String,
        /// Where the group opens, in bytes from the list's start.
        at: usize,
    },
    /// The list expands to more hosts than a step can have, which bounds the memory an expansion
    /// may take.
    #[error("the host list names more than {MAX_HOSTS} hosts")]
    TooMany,
}

/// Every host that `list` names, in order.
pub fn expand(list: &str) -> Result<Vec<String>, HostlistError> {
    if list.is_empty() {
        return Err(HostlistError::Empty);
    }
    let mut hosts = Vec::new();
    for (start, expression) in split_top_level(list)? {
        let segments = parse_expression(expression, start)?;
        let count = segments.iter().try_fold(1usize, |count, segment| {
            let n = match segment {
                Segment::Text(_) => 1,
                Segment::Ids(ids) => ids.len(),
            };
            count
                .checked_mul(n)
                .filter(|&total| total + hosts.len() <= MAX_HOSTS)
                .ok_or(HostlistError::TooMany)
        })?;
        let mut names = vec![String::new()];
        for segment in &segments {
            names = match segment {
                Segment::Text(text) => names.into_iter().map(|name| name + text).collect(),
                // The names so far vary slowest: the first group is the outermost loop.
                Segment::Ids(ids) => names
                    .iter()
                    .flat_map(|name| ids.iter().map(move |id| format!("{name}{id}")))
                    .collect(),
            };
        }
        debug_assert_eq!(names.len(), count);
        hosts.extend(names);
    }
    Ok(hosts)
}

/// A piece of one expression: literal text, or a bracket group's ids already written out.
enum Segment {
    Text(String),
    Ids(Vec<String>),
}

/// The expressions of `list` with their offsets: commas split only outside brackets.
fn split_top_level(list: &str) -> Result<Vec<(usize, &str)>, HostlistError> {
    let mut expressions = Vec::new();
    let mut open: Option<usize> = None;
    let mut start = 0;
    for (at, c) in list.char_indices() {
        match c {
            '[' if open.is_some() => return Err(HostlistError::Nested { at }),
            '[' => open = Some(at),
            ']' if open.is_none() => return Err(HostlistError::Unopened { at }),
            ']' => open = None,
            ',' if open.is_none() => {
                expressions.push((start, &list[start..at]));
                start = at + 1;
            }
            _ => {}
        }
    }
    if let Some(at) = open {
        return Err(HostlistError::Unclosed { at });
    }
    expressions.push((start, &list[start..]));
    match expressions.iter().find(|(_, e)| e.is_empty()) {
        Some(&(at, _)) => Err(HostlistError::EmptyName { at }),
        None => Ok(expressions),
    }
}

/// One expression (brackets balanced and unnested, as `split_top_level` checked) as segments.
fn parse_expression(expression: &str, offset: usize) -> Result<Vec<Segment>, HostlistError> {
    let mut segments = Vec::new();
    let mut rest = expression;
    let mut at = offset;
    while !rest.is_empty() {
        if let Some(group) = rest.strip_prefix('[') {
            let close = group
                .find(']')
                .expect("invariant: split_top_level checked every `[` is closed");
            segments.push(Segment::Ids(parse_group(&group[..close], at)?));
            rest = &group[close + 1..];
            at += close + 2;
        } else {
            let end = rest.find('[').unwrap_or(rest.len());
            let text = &rest[..end];
            if let Some((i, found)) = text
                .char_indices()
                .find(|&(_, c)| c.is_whitespace() || c.is_control())
            {
                return Err(HostlistError::BadCharacter { found, at: at + i });
            }
            segments.push(Segment::Text(text.to_owned()));
            rest = &rest[end..];
            at += end;
        }
    }
    Ok(segments)
}

/// The ids of a bracket group's contents (`1,3,5-7`), each range padded to its low end's width.
fn parse_group(group: &str, at: usize) -> Result<Vec<String>, HostlistError> {
    let mut ids = Vec::new();
    for entry in group.split(',') {
        if entry.is_empty() {
            return Err(HostlistError::EmptyRange { at });
        }
        let (lo, hi) = entry.split_once('-').unwrap_or((entry, entry));
        let bad = || HostlistError::BadNumber {
            text: entry.to_owned(),
            at,
        };
        let (low, high) = (number(lo).ok_or_else(bad)?, number(hi).ok_or_else(bad)?);
        if low > high {
            return Err(HostlistError::Backwards {
                lo: lo.to_owned(),
                hi: hi.to_owned(),
                at,
            });
        }
        if (high - low) as usize >= MAX_HOSTS - ids.len().min(MAX_HOSTS) {
            return Err(HostlistError::TooMany);
        }
        let width = lo.len();
        ids.extend((low..=high).map(|id| format!("{id:0width$}")));
    }
    Ok(ids)
}

/// A run of ASCII digits as a number; at most 18 digits, so that it fits a u64 with room.
fn number(text: &str) -> Option<u64> {
    let digits = !text.is_empty() && text.len() <= 18 && text.bytes().all(|b| b.is_ascii_digit());
    digits.then(|| text.parse().expect("invariant: at most 18 ASCII digits"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hosts(list: &str) -> Vec<String> {
        expand(list).unwrap_or_else(|e| panic!("{list}: {e}"))
    }

    fn names(names: &[&str]) -> Vec<String> {
        names.iter().map(|n| n.to_string()).collect()
    }

    #[test]
    fn a_single_host_is_itself() {
        assert_eq!(hosts("login1"), names(&["login1"]));
        assert_eq!(hosts("localhost"), names(&["localhost"]));
    }

    #[test]
    fn ranges_expand_in_order() {
        assert_eq!(hosts("n[1-3]"), names(&["n1", "n2", "n3"]));
        // Without padding, widths grow with the numbers.
        assert_eq!(
            hosts("foo[8-11]"),
            names(&["foo8", "foo9", "foo10", "foo11"])
        );
    }

    #[test]
    fn zero_padding_follows_the_low_end() {
        let expanded = hosts("n[001-010]");
        assert_eq!(expanded.len(), 10);
        assert_eq!(expanded[0], "n001");
        assert_eq!(expanded[8], "n009");
        assert_eq!(expanded[9], "n010");
        assert_eq!(hosts("n[08-11]"), names(&["n08", "n09", "n10", "n11"]));
    }

    #[test]
    fn lists_inside_brackets_mix_numbers_and_ranges() {
        assert_eq!(hosts("n[1,3,5-7]"), names(&["n1", "n3", "n5", "n6", "n7"]));
        // Written order is kept, even when not sorted.
        assert_eq!(hosts("n[7,2]"), names(&["n7", "n2"]));
    }

    #[test]
    fn commas_outside_brackets_separate_groups_with_their_own_prefixes() {
        assert_eq!(hosts("a[1-2],b3"), names(&["a1", "a2", "b3"]));
        assert_eq!(
            hosts("gpu[01-02],cpu[1,4],login"),
            names(&["gpu01", "gpu02", "cpu1", "cpu4", "login"])
        );
    }

    #[test]
    fn dashes_belong_to_host_names_outside_brackets() {
        assert_eq!(
            hosts("rack-1-n[01-04]"),
            names(&["rack-1-n01", "rack-1-n02", "rack-1-n03", "rack-1-n04"])
        );
        assert_eq!(hosts("my-login-node"), names(&["my-login-node"]));
    }

    #[test]
    fn several_groups_are_a_cartesian_product_first_group_outermost() {
        assert_eq!(
            hosts("r[1-2]n[1-2]"),
            names(&["r1n1", "r1n2", "r2n1", "r2n2"])
        );
        assert_eq!(
            hosts("rack[01-2]-node[1,5]-ib"),
            names(&[
                "rack01-node1-ib",
                "rack01-node5-ib",
                "rack02-node1-ib",
                "rack02-node5-ib"
            ])
        );
    }

    #[test]
    fn a_group_may_stand_alone_or_end_a_name() {
        assert_eq!(hosts("[1-2]"), names(&["1", "2"]));
        assert_eq!(hosts("n[1-2]x"), names(&["n1x", "n2x"]));
    }

    #[test]
    fn malformed_lists_say_what_and_where() {
        use HostlistError::*;
        let cases: [(&str, HostlistError); 13] = [
            ("", Empty),
            ("a,,b", EmptyName { at: 2 }),
            ("a,", EmptyName { at: 2 }),
            (",a", EmptyName { at: 0 }),
            ("n[1-3", Unclosed { at: 1 }),
            ("n1-3]", Unopened { at: 4 }),
            ("n[1[2]]", Nested { at: 3 }),
            ("n[]", EmptyRange { at: 1 }),
            ("n[1,,2]", EmptyRange { at: 1 }),
            (
                "n[a-b]",
                BadNumber {
                    text: "a-b".into(),
                    at: 1,
                },
            ),
            (
                "n[1-2-3]",
                BadNumber {
                    text: "1-2-3".into(),
                    at: 1,
                },
            ),
            (
                "x,n[3-1]",
                Backwards {
                    lo: "3".into(),
                    hi: "1".into(),
                    at: 3,
                },
            ),
            ("n1 n2", BadCharacter { found: ' ', at: 2 }),
        ];
        for (list, error) in cases {
            assert_eq!(expand(list), Err(error), "{list:?}");
        }
        assert!(matches!(expand("n[-1]"), Err(BadNumber { .. })));
        assert!(matches!(expand("n[1-]"), Err(BadNumber { .. })));
        assert!(matches!(expand("n[+1]"), Err(BadNumber { .. })));
        // The message names the offending piece, for the user who reads it.
        let message = expand("gpu[01-x]").unwrap_err().to_string();
        assert!(
            message.contains("01-x") && message.contains("offset 3"),
            "{message}"
        );
    }

    #[test]
    fn huge_lists_are_refused_not_allocated() {
        assert_eq!(expand("n[0-999999999]"), Err(HostlistError::TooMany));
        assert_eq!(
            expand("a[0-1023]b[0-1023]c[0-1]"),
            Err(HostlistError::TooMany)
        );
        assert_eq!(
            expand("n[1-1234567890123456789]"),
            Err(HostlistError::BadNumber {
                text: "1-1234567890123456789".into(),
                at: 1
            })
        );
        // Just at the limit is fine.
        assert_eq!(expand("a[0-1023]b[0-1023]").unwrap().len(), MAX_HOSTS);
    }
}
