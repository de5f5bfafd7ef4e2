//! The URDF pre-scan: a light, non-recursive reading of the XML's elements and attributes.

use super::*;

// ---------------------------------------------------------------------------------------------
// The pre-scan: a light, non-recursive reading of the XML's elements and attributes, run before
// urdf-rs (which recurses per nesting level) so that the nesting is bounded and a malformed
// attribute is reported with its element. It stops quietly at anything it does not understand
// (urdf-rs then reports the malformed XML); only the nesting depth is an error here.

/// One element of the pre-scanned XML.
pub(super) struct XmlElem {
    /// Tag name.
    pub(super) name: String,
    /// Attributes in document order, values with the five predefined entities decoded.
    pub(super) attrs: Vec<(String, String)>,
    /// Index of the parent element (None for the root).
    pub(super) parent: Option<usize>,
    /// Line (from 1) of the element's `<`.
    pub(super) line: usize,
    /// Whether the element holds non-whitespace text.
    pub(super) has_text: bool,
}

impl XmlElem {
    pub(super) fn attr(&self, name: &str) -> Option<&str> {
        self.attrs.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }
}

/// Decodes `&lt; &gt; &amp; &quot; &apos;` (other references are kept as written).
fn decode_entities(v: &str) -> String {
    if !v.contains('&') {
        return v.to_string();
    }
    v.replace("&lt;", "<").replace("&gt;", ">").replace("&quot;", "\"").replace("&apos;", "'").replace("&amp;", "&")
}

/// How the pre-scan ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ScanEnd {
    /// Every element was read and closed.
    Complete,
    /// The text ends inside this element (a truncated file).
    EndsInside(usize),
    /// The scan met something it does not read (malformed XML, a mismatched end tag): urdf-rs reports it.
    Stopped,
}

/// The elements of `text` in document order and how the scan ended. Errors (one line) when
/// elements nest deeper than [`MAX_URDF_DEPTH`].
pub(super) fn scan_xml(text: &str) -> std::result::Result<(Vec<XmlElem>, ScanEnd), String> {
    let b = text.as_bytes();
    let lines_in = |from: usize, to: usize| b[from..to.min(b.len())].iter().filter(|&&c| c == b'\n').count();
    let find = |from: usize, pat: &str| text.get(from..).and_then(|r| r.find(pat)).map(|k| from + k);
    let mut elems: Vec<XmlElem> = Vec::new();
    let mut open: Vec<usize> = Vec::new(); // indices of the elements not yet closed
    let mut i = 0;
    let mut line = 1;
    while i < b.len() {
        // text up to the next '<'
        let next = find(i, "<").unwrap_or(b.len());
        if let Some(&top) = open.last()
            && !text[i..next].trim().is_empty()
        {
            elems[top].has_text = true;
        }
        line += lines_in(i, next);
        i = next;
        if i >= b.len() {
            break;
        }
        let rest = &text[i..];
        // comments, CDATA, processing instructions, DOCTYPE: skipped
        let skip_to = |end: &str, start_len: usize| find(i + start_len, end).map(|k| k + end.len());
        let skipped = if rest.starts_with("<!--") {
            Some(skip_to("-->", 4))
        } else if rest.starts_with("<![CDATA[") {
            if let Some(&top) = open.last() {
                elems[top].has_text = true;
            }
            Some(skip_to("]]>", 9))
        } else if rest.starts_with("<?") {
            Some(skip_to("?>", 2))
        } else if rest.starts_with("<!") {
            // DOCTYPE, possibly with an internal subset in [ ]
            let mut depth = 0i32;
            let mut end = None;
            for (k, &c) in b[i..].iter().enumerate() {
                match c {
                    b'[' => depth += 1,
                    b']' => depth -= 1,
                    b'>' if depth <= 0 => {
                        end = Some(i + k + 1);
                        break;
                    }
                    _ => {}
                }
            }
            Some(end)
        } else {
            None
        };
        if let Some(end) = skipped {
            let Some(end) = end else { return Ok((elems, ScanEnd::Stopped)) };
            line += lines_in(i, end);
            i = end;
            continue;
        }
        if rest.starts_with("</") {
            let Some(end) = find(i, ">") else { return Ok((elems, ScanEnd::Stopped)) };
            let closing = text[i + 2..end].trim();
            match open.last() {
                Some(&top) if elems[top].name == closing => {}
                _ => return Ok((elems, ScanEnd::Stopped)),
            }
            line += lines_in(i, end);
            open.pop();
            i = end + 1;
            continue;
        }
        // a start tag: <name attr="v" ...> or .../>
        let tag_line = line;
        let mut k = i + 1;
        let name_end = b[k..].iter().position(|c| c.is_ascii_whitespace() || *c == b'/' || *c == b'>').map_or(b.len(), |p| k + p);
        let name = &text[k..name_end];
        if name.is_empty() {
            return Ok((elems, ScanEnd::Stopped));
        }
        k = name_end;
        let mut attrs = Vec::new();
        let mut self_closing = false;
        let mut complete = false;
        while k < b.len() {
            match b[k] {
                c if c.is_ascii_whitespace() => {
                    if c == b'\n' {
                        line += 1;
                    }
                    k += 1;
                }
                b'>' => {
                    k += 1;
                    complete = true;
                    break;
                }
                b'/' if b.get(k + 1) == Some(&b'>') => {
                    k += 2;
                    self_closing = true;
                    complete = true;
                    break;
                }
                _ => {
                    let Some(eq) = find(k, "=") else { break };
                    let key = text[k..eq].trim();
                    if key.is_empty() || key.contains(['<', '>', '"', '\'']) {
                        break;
                    }
                    let mut v = eq + 1;
                    while v < b.len() && b[v].is_ascii_whitespace() {
                        v += 1;
                    }
                    let Some(&q) = b.get(v).filter(|&&q| q == b'"' || q == b'\'') else { break };
                    let Some(close) = find(v + 1, if q == b'"' { "\"" } else { "'" }) else { break };
                    line += lines_in(k, close);
                    attrs.push((key.to_string(), decode_entities(&text[v + 1..close])));
                    k = close + 1;
                }
            }
        }
        if !complete {
            return Ok((elems, ScanEnd::Stopped));
        }
        let depth = open.len() + 1;
        if depth > MAX_URDF_DEPTH {
            let path: Vec<&str> = open.iter().take(4).map(|&e| elems[e].name.as_str()).collect();
            return Err(format!(
                "line {tag_line}: element <{}> is nested {depth} levels deep (in <{}> …); expected at most {MAX_URDF_DEPTH} levels (a URDF nests 5: robot > link > collision > geometry > box)",
                clip(name, MAX_QUOTED_CHARS),
                path.join("> <")
            ));
        }
        elems.push(XmlElem { name: name.to_string(), attrs, parent: open.last().copied(), line: tag_line, has_text: false });
        if !self_closing {
            open.push(elems.len() - 1);
        }
        i = k;
    }
    let end = match open.last() {
        None => ScanEnd::Complete,
        Some(&e) => ScanEnd::EndsInside(e),
    };
    Ok((elems, end))
}

/// How urdf-rs reads an attribute.
#[derive(Clone, Copy)]
enum AttrKind {
    /// Any text.
    Text,
    /// One number (`f64`).
    Number,
    /// `n` numbers separated by spaces.
    Numbers(usize),
    /// A joint type.
    JointType,
}

const JOINT_TYPES: [&str; 7] = ["revolute", "continuous", "prismatic", "fixed", "floating", "planar", "spherical"];

/// What urdf-rs requires of an element under a given parent: `(attribute, kind, required)`,
/// the child elements it requires, and those it reads at most once.
struct ElemRule {
    attrs: &'static [(&'static str, AttrKind, bool)],
    required_children: &'static [&'static str],
    single_children: &'static [&'static str],
}

fn elem_rule(parent: &str, name: &str, v12: bool) -> Option<ElemRule> {
    use AttrKind::*;
    const NONE: &[&str] = &[];
    const NO_ATTRS: &[(&str, AttrKind, bool)] = &[];
    const ORIGIN: &[(&str, AttrKind, bool)] = &[("xyz", Numbers(3), false), ("rpy", Numbers(3), false)];
    fn rule(
        attrs: &'static [(&'static str, AttrKind, bool)],
        required_children: &'static [&'static str],
        single_children: &'static [&'static str],
    ) -> Option<ElemRule> {
        Some(ElemRule { attrs, required_children, single_children })
    }
    match (parent, name) {
        ("robot", "link") => rule(&[("name", Text, true)], NONE, &["inertial"]),
        ("robot", "joint") => rule(
            &[("name", Text, true), ("type", JointType, true)],
            &["parent", "child"],
            &["origin", "parent", "child", "axis", "limit", "calibration", "dynamics", "mimic", "safety_controller"],
        ),
        ("robot" | "visual", "material") => rule(&[("name", Text, true)], NONE, &["color", "texture"]),
        ("material", "color") => rule(&[("rgba", Numbers(4), true)], NONE, NONE),
        ("material", "texture") => rule(&[("filename", Text, true)], NONE, NONE),
        ("link", "inertial") => rule(NO_ATTRS, &["mass", "inertia"], &["origin", "mass", "inertia"]),
        ("link", "visual") => rule(NO_ATTRS, &["geometry"], &["origin", "geometry", "material"]),
        ("link", "collision") => rule(NO_ATTRS, &["geometry"], &["origin", "geometry"]),
        ("inertial", "mass") => rule(&[("value", Number, true)], NONE, NONE),
        ("inertial", "inertia") => rule(
            &[("ixx", Number, true), ("ixy", Number, true), ("ixz", Number, true), ("iyy", Number, true), ("iyz", Number, true), ("izz", Number, true)],
            NONE,
            NONE,
        ),
        ("inertial" | "visual" | "collision" | "joint", "origin") => rule(ORIGIN, NONE, NONE),
        ("visual" | "collision", "geometry") => rule(NO_ATTRS, NONE, NONE),
        ("geometry", "box") => rule(&[("size", Numbers(3), true)], NONE, NONE),
        ("geometry", "cylinder" | "capsule") => rule(&[("radius", Number, true), ("length", Number, true)], NONE, NONE),
        ("geometry", "sphere") => rule(&[("radius", Number, true)], NONE, NONE),
        ("geometry", "mesh") => rule(&[("filename", Text, true), ("scale", Numbers(3), false)], NONE, NONE),
        ("joint", "parent" | "child") => rule(&[("link", Text, true)], NONE, NONE),
        ("joint", "axis") => rule(&[("xyz", Numbers(3), true)], NONE, NONE),
        // URDF 1.2: urdf-rs fills in a missing velocity (infinite)
        ("joint", "limit") if v12 => rule(
            &[("lower", Number, false), ("upper", Number, false), ("effort", Number, false), ("velocity", Number, false)],
            NONE,
            NONE,
        ),
        ("joint", "limit") => rule(
            &[("lower", Number, false), ("upper", Number, false), ("effort", Number, false), ("velocity", Number, true)],
            NONE,
            NONE,
        ),
        ("joint", "mimic") => rule(&[("joint", Text, true), ("multiplier", Number, false), ("offset", Number, false)], NONE, NONE),
        ("joint", "dynamics") => rule(&[("damping", Number, false), ("friction", Number, false)], NONE, NONE),
        ("joint", "calibration") => rule(&[("rising", Number, false), ("falling", Number, false)], NONE, NONE),
        ("joint", "safety_controller") => rule(
            &[("soft_lower_limit", Number, false), ("soft_upper_limit", Number, false), ("k_position", Number, false), ("k_velocity", Number, true)],
            NONE,
            NONE,
        ),
        _ => None,
    }
}

/// "joint 'x'" / "link 'y'" / "material 'z'" for the nearest named link, joint or material
/// enclosing element `i` (itself included), else "<name>".
pub(super) fn owner_of(elems: &[XmlElem], i: usize) -> String {
    let mut k = Some(i);
    while let Some(e) = k {
        let el = &elems[e];
        if matches!(el.name.as_str(), "link" | "joint" | "material")
            && let Some(n) = el.attr("name")
        {
            return format!("{} '{}'", el.name, clip(n, MAX_QUOTED_CHARS));
        }
        k = el.parent;
    }
    format!("<{}>", elems[i].name)
}

/// Checks the elements urdf-rs reads against what it requires: the first problem, as "line N:
/// <owner>: <what>; expected …", or None.
pub(super) fn check_urdf_elements(elems: &[XmlElem]) -> Option<String> {
    let root = elems.first()?;
    if root.name != "robot" {
        return Some(format!("line {}: the root element is <{}>; expected <robot>", root.line, clip(&root.name, MAX_QUOTED_CHARS)));
    }
    let v12 = root
        .attr("version")
        .and_then(|v| v.trim().split_once('.'))
        .and_then(|(a, b)| Some((a.parse::<u32>().ok()?, b.parse::<u32>().ok()?)))
        .is_some_and(|v| v >= (1, 2));
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); elems.len()];
    for (i, e) in elems.iter().enumerate() {
        if let Some(p) = e.parent {
            children[p].push(i);
        }
    }
    for (i, e) in elems.iter().enumerate() {
        let Some(p) = e.parent else { continue };
        let parent = elems[p].name.as_str();
        let Some(rule) = elem_rule(parent, &e.name, v12) else {
            if parent == "geometry" && matches!(elems[p].parent.map(|g| elems[g].name.as_str()), Some("visual" | "collision")) {
                return Some(format!(
                    "line {}: {}: unknown geometry <{}>; expected <box>, <cylinder>, <capsule>, <sphere> or <mesh>",
                    e.line,
                    owner_of(elems, i),
                    clip(&e.name, MAX_QUOTED_CHARS)
                ));
            }
            continue;
        };
        let at = |what: String, expected: String| Some(format!("line {}: {}: <{}> {what}; expected {expected}", e.line, owner_of(elems, i), e.name));
        for &(attr, kind, required) in rule.attrs {
            let Some(v) = e.attr(attr) else {
                if required {
                    return at(format!("has no attribute `{attr}`"), format!("{} `{attr}`", kind_words(kind)));
                }
                continue;
            };
            let quoted = format!("{:?}", clip(v, MAX_QUOTED_CHARS));
            let ok = match kind {
                AttrKind::Text => true,
                AttrKind::Number => v.trim().parse::<f64>().is_ok(),
                AttrKind::Numbers(n) => {
                    let parts: Vec<&str> = v.split_whitespace().collect();
                    parts.len() == n && parts.iter().all(|x| x.parse::<f64>().is_ok())
                }
                AttrKind::JointType => JOINT_TYPES.contains(&v),
            };
            if !ok {
                let expected = match kind {
                    AttrKind::JointType => format!("`type` to be one of {}", JOINT_TYPES.join(", ")),
                    _ => format!("{} `{attr}`", kind_words(kind)),
                };
                return at(format!("has `{attr}` = {quoted}"), expected);
            }
        }
        let kids = &children[i];
        for &req in rule.required_children {
            if !kids.iter().any(|&c| elems[c].name == req) {
                return at(format!("has no <{req}>"), format!("a <{req}> inside <{}>", e.name));
            }
        }
        for &single in rule.single_children {
            let n = kids.iter().filter(|&&c| elems[c].name == single).count();
            if n > 1 {
                return at(format!("has {n} <{single}> elements"), format!("at most one <{single}> inside <{}>", e.name));
            }
        }
        if e.name == "geometry" {
            let n = kids.len();
            if n != 1 {
                return at(format!("holds {n} shapes"), "exactly one of <box>, <cylinder>, <capsule>, <sphere>, <mesh>".into());
            }
        }
        if e.has_text {
            return at("holds text".into(), format!("only attributes and child elements in <{}>", e.name));
        }
    }
    None
}

/// What an attribute of a kind should hold, in words.
fn kind_words(kind: AttrKind) -> String {
    match kind {
        AttrKind::Text => "a value for".into(),
        AttrKind::Number => "one number in".into(),
        AttrKind::Numbers(n) => format!("{n} numbers separated by spaces in"),
        AttrKind::JointType => "a joint type in".into(),
    }
}
