//! JSON (RFC 8259) reader that keeps object keys in order, rejects duplicate keys and keeps
//! numbers as text (so they can be parsed exactly, as f32 or f64). Python's `NaN`, `Infinity`
//! and `-Infinity` are read as numbers so that the error names the field they are in.

use std::fmt;

pub enum Value {
    Null,
    Bool(bool),
    /// The number's text (`NaN`, `inf`, `-inf` for Python's non-standard tokens).
    Num(String),
    Str(String),
    Arr(Vec<Value>),
    Obj(Vec<(String, Value)>),
}

pub struct Error {
    pos: usize,
    path: String,
    msg: String,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "invalid JSON at byte {}", self.pos)?;
        if !self.path.is_empty() {
            write!(f, " (in field `{}`)", self.path)?;
        }
        write!(f, ": {}", self.msg)
    }
}

const MAX_DEPTH: usize = 64;

pub fn parse(text: &str) -> Result<Value, Error> {
    let mut p = Parser { text, s: text.as_bytes(), pos: 0, path: Vec::new() };
    let v = p.value()?;
    p.ws();
    if p.pos != p.s.len() {
        return Err(p.err(format!("expected the end of the message, got {}", p.got())));
    }
    Ok(v)
}

struct Parser<'a> {
    text: &'a str,
    s: &'a [u8],
    pos: usize,
    path: Vec<String>,
}

impl Parser<'_> {
    fn err(&self, msg: String) -> Error {
        Error { pos: self.pos, path: self.path.join("."), msg }
    }

    fn got(&self) -> String {
        match self.text.get(self.pos..).and_then(|r| r.chars().next()) {
            Some(c) => format!("{c:?}"),
            None => "the end of the message".into(),
        }
    }

    fn ws(&mut self) {
        while self.pos < self.s.len() && matches!(self.s[self.pos], b' ' | b'\t' | b'\n' | b'\r') {
            self.pos += 1;
        }
    }

    fn eat(&mut self, lit: &str) -> bool {
        if self.s[self.pos..].starts_with(lit.as_bytes()) {
            self.pos += lit.len();
            true
        } else {
            false
        }
    }

    fn value(&mut self) -> Result<Value, Error> {
        self.ws();
        let Some(&c) = self.s.get(self.pos) else {
            return Err(self.err("expected a value, got the end of the message".into()));
        };
        match c {
            b'{' => self.object(),
            b'[' => self.array(),
            b'"' => Ok(Value::Str(self.string()?)),
            b'-' | b'0'..=b'9' => {
                if self.eat("-Infinity") {
                    Ok(Value::Num("-inf".into()))
                } else {
                    self.number()
                }
            }
            _ if self.eat("true") => Ok(Value::Bool(true)),
            _ if self.eat("false") => Ok(Value::Bool(false)),
            _ if self.eat("null") => Ok(Value::Null),
            _ if self.eat("NaN") => Ok(Value::Num("NaN".into())),
            _ if self.eat("Infinity") => Ok(Value::Num("inf".into())),
            _ => Err(self.err(format!("expected a value, got {}", self.got()))),
        }
    }

    fn enter(&mut self) -> Result<(), Error> {
        if self.path.len() >= MAX_DEPTH {
            return Err(self.err(format!("expected at most {MAX_DEPTH} levels of nesting")));
        }
        self.pos += 1;
        Ok(())
    }

    fn object(&mut self) -> Result<Value, Error> {
        self.enter()?;
        let mut entries: Vec<(String, Value)> = Vec::new();
        self.ws();
        if self.eat("}") {
            return Ok(Value::Obj(entries));
        }
        loop {
            self.ws();
            if self.s.get(self.pos) != Some(&b'"') {
                return Err(self.err(format!("expected a key in double quotes, got {}", self.got())));
            }
            let key_pos = self.pos;
            let key = self.string()?;
            if entries.iter().any(|(k, _)| *k == key) {
                self.pos = key_pos;
                return Err(self.err(format!("duplicate key {key:?}: expected each key once")));
            }
            self.ws();
            if !self.eat(":") {
                return Err(self.err(format!("expected `:` after the key {key:?}, got {}", self.got())));
            }
            self.path.push(key.clone());
            let v = self.value()?;
            self.path.pop();
            entries.push((key, v));
            self.ws();
            if self.eat(",") {
                continue;
            }
            if self.eat("}") {
                return Ok(Value::Obj(entries));
            }
            return Err(self.err(format!("expected `,` or `}}`, got {}", self.got())));
        }
    }

    fn array(&mut self) -> Result<Value, Error> {
        self.enter()?;
        let mut items = Vec::new();
        self.ws();
        if self.eat("]") {
            return Ok(Value::Arr(items));
        }
        loop {
            self.path.push(items.len().to_string());
            let v = self.value()?;
            self.path.pop();
            items.push(v);
            self.ws();
            if self.eat(",") {
                continue;
            }
            if self.eat("]") {
                return Ok(Value::Arr(items));
            }
            return Err(self.err(format!("expected `,` or `]`, got {}", self.got())));
        }
    }

    fn hex4(&mut self) -> Result<u32, Error> {
        let digits = self.text.get(self.pos..self.pos + 4).filter(|d| d.bytes().all(|b| b.is_ascii_hexdigit()));
        let Some(d) = digits else {
            return Err(self.err("expected 4 hex digits after `\\u`".into()));
        };
        let v = u32::from_str_radix(d, 16).map_err(|_| self.err("expected 4 hex digits after `\\u`".into()))?;
        self.pos += 4;
        Ok(v)
    }

    /// At a `"`: reads the string and its escapes.
    fn string(&mut self) -> Result<String, Error> {
        self.pos += 1;
        let mut out = String::new();
        loop {
            let start = self.pos;
            while self.pos < self.s.len() && !matches!(self.s[self.pos], b'"' | b'\\' | 0..=0x1f) {
                self.pos += 1;
            }
            // Stopped at an ASCII byte (or the end), so this is a char boundary.
            out.push_str(&self.text[start..self.pos]);
            let Some(&c) = self.s.get(self.pos) else {
                return Err(self.err("expected a closing `\"`, got the end of the message".into()));
            };
            match c {
                b'"' => {
                    self.pos += 1;
                    return Ok(out);
                }
                b'\\' => {
                    self.pos += 1;
                    let Some(&e) = self.s.get(self.pos) else {
                        return Err(self.err("expected an escape after `\\`, got the end of the message".into()));
                    };
                    self.pos += 1;
                    match e {
                        b'"' => out.push('"'),
                        b'\\' => out.push('\\'),
                        b'/' => out.push('/'),
                        b'b' => out.push('\u{8}'),
                        b'f' => out.push('\u{c}'),
                        b'n' => out.push('\n'),
                        b'r' => out.push('\r'),
                        b't' => out.push('\t'),
                        b'u' => {
                            let hi = self.hex4()?;
                            let code = if (0xD800..0xDC00).contains(&hi) {
                                if !self.eat("\\u") {
                                    return Err(self.err("expected a low surrogate `\\uDC00`…`\\uDFFF`".into()));
                                }
                                let lo = self.hex4()?;
                                if !(0xDC00..0xE000).contains(&lo) {
                                    return Err(self.err("expected a low surrogate `\\uDC00`…`\\uDFFF`".into()));
                                }
                                0x10000 + ((hi - 0xD800) << 10) + (lo - 0xDC00)
                            } else {
                                hi
                            };
                            let Some(ch) = char::from_u32(code) else {
                                return Err(self.err(format!("expected a Unicode scalar value, got \\u{hi:04x}")));
                            };
                            out.push(ch);
                        }
                        _ => {
                            self.pos -= 1;
                            return Err(self.err(format!(
                                "expected a JSON escape, got `\\{}`",
                                self.got().trim_matches('\'')
                            )));
                        }
                    }
                }
                _ => return Err(self.err("expected no raw control characters in a string (escape them)".into())),
            }
        }
    }

    fn digits(&mut self) -> usize {
        let start = self.pos;
        while self.pos < self.s.len() && self.s[self.pos].is_ascii_digit() {
            self.pos += 1;
        }
        self.pos - start
    }

    fn number(&mut self) -> Result<Value, Error> {
        let start = self.pos;
        self.eat("-");
        if !self.eat("0") && self.digits() == 0 {
            return Err(self.err(format!("expected a digit, got {}", self.got())));
        }
        if self.eat(".") && self.digits() == 0 {
            return Err(self.err(format!("expected a digit after `.`, got {}", self.got())));
        }
        if self.eat("e") || self.eat("E") {
            let _ = self.eat("+") || self.eat("-");
            if self.digits() == 0 {
                return Err(self.err(format!("expected a digit in the exponent, got {}", self.got())));
            }
        }
        Ok(Value::Num(self.text[start..self.pos].to_string()))
    }
}
