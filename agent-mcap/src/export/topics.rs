//! Topic names as ROS 2 allows them (the rules of ROS 2's "Topic and Service
//! name mapping" design, as `rcl` checks a fully qualified name): a leading
//! `/`, tokens of ASCII letters, digits and `_` separated by one `/`, none
//! starting with a digit, no `__`, no trailing `/`.
//!
//! A topic that breaks them is made valid: every other character becomes
//! `_`, runs of `_` become one, empty tokens go, a token that starts with a
//! digit gets a leading `_`; a name another topic already has gets `_2`,
//! `_3`, ... A valid topic is kept as it is.

use std::collections::{HashMap, HashSet};

/// `topic` made a valid fully qualified ROS 2 topic name (see the module's
/// documentation).
fn valid(topic: &str) -> String {
    let mut out = String::new();
    for token in topic.split('/') {
        let mut t = String::new();
        for c in token.chars() {
            let c = if c.is_ascii_alphanumeric() { c } else { '_' };
            if !(c == '_' && t.ends_with('_')) {
                t.push(c);
            }
        }
        if t.is_empty() {
            continue;
        }
        if t.starts_with(|c: char| c.is_ascii_digit()) {
            t.insert(0, '_');
        }
        out.push('/');
        out.push_str(&t);
    }
    if out.is_empty() {
        out.push_str("/unnamed");
    }
    out
}

/// The ROS 2 name of each of `topics`, in order: a valid one kept, another
/// made valid and, if that name is taken, numbered.
pub(crate) fn ros2_topics(topics: &[&str]) -> Vec<String> {
    let mut taken: HashSet<String> = topics
        .iter()
        .filter(|t| valid(t) == **t)
        .map(|t| (*t).to_owned())
        .collect();
    let mut made: HashMap<&str, String> = HashMap::new();
    topics
        .iter()
        .map(|&t| {
            let want = valid(t);
            if want == t {
                return want;
            }
            if let Some(name) = made.get(t) {
                return name.clone();
            }
            let mut name = want.clone();
            let mut k = 1;
            while taken.contains(&name) {
                k += 1;
                name = format!("{}_{k}", want.trim_end_matches('_'));
            }
            taken.insert(name.clone());
            made.insert(t, name.clone());
            name
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn valid_topics_are_kept_and_others_made_valid_and_unique() {
        let topics = [
            "/links/e11/c1/q_est/to/c1",
            "/links/r11/c1/A4x4/to/c1",
            "relative/name",
            "/a//b/",
            "/links/my-node/x.y/to/2d",
            "/a__b/~/{ns}",
            "/a_b",
            "/a__b",
            "/",
            "/links/my_node/x_y/to/_2d",
            "/links/my-node/x.y/to/2d",
        ];
        assert_eq!(
            ros2_topics(&topics),
            [
                "/links/e11/c1/q_est/to/c1",
                "/links/r11/c1/A4x4/to/c1",
                "/relative/name",
                "/a/b",
                "/links/my_node/x_y/to/_2d_2",
                "/a_b/_/_ns_",
                "/a_b",
                "/a_b_2",
                "/unnamed",
                "/links/my_node/x_y/to/_2d",
                "/links/my_node/x_y/to/_2d_2",
            ]
        );
    }
}
