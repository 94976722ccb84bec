//! OpenDDL (Open Data Description Language, the syntax of OpenGEX and of `.mymaterial` files):
//! a lexer and parser producing a tree of structures with typed data and source positions.
//!
//! Covers the 3.0 grammar: custom structures with `$global` / `%local` names and property lists,
//! primitive structures (`float {…}`, `float[3] {{…}, …}`), all literal forms (decimal, hex `0x`,
//! octal `0o`, binary `0b`, character, float with exponent, `true`/`false`, concatenated strings
//! with escapes, references, type names), `//` and `/* */` comments and any line endings.

use std::fmt;

use base::diagnostic::TextPosition;

/// A syntax or type error, with its position in the text.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct OpenDdlError {
    pub position: TextPosition,
    pub message: String,
}

/// A primitive data type.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DataType {
    Bool,
    Int8,
    Int16,
    Int32,
    Int64,
    UInt8,
    UInt16,
    UInt32,
    UInt64,
    Half,
    Float,
    Double,
    String,
    Ref,
    Type,
}

impl DataType {
    pub(crate) fn from_identifier(identifier: &str) -> Option<DataType> {
        Some(match identifier {
            "bool" | "b" => DataType::Bool,
            "int8" | "i8" => DataType::Int8,
            "int16" | "i16" => DataType::Int16,
            "int32" | "i32" => DataType::Int32,
            "int64" | "i64" => DataType::Int64,
            "unsigned_int8" | "uint8" | "u8" => DataType::UInt8,
            "unsigned_int16" | "uint16" | "u16" => DataType::UInt16,
            "unsigned_int32" | "uint32" | "u32" => DataType::UInt32,
            "unsigned_int64" | "uint64" | "u64" => DataType::UInt64,
            "half" | "float16" | "h" => DataType::Half,
            "float" | "float32" | "f" => DataType::Float,
            "double" | "float64" | "d" => DataType::Double,
            "string" | "s" => DataType::String,
            "ref" | "r" => DataType::Ref,
            "type" | "t" => DataType::Type,
            _ => return None,
        })
    }

    fn integer_range(self) -> Option<(i128, i128)> {
        Some(match self {
            DataType::Int8 => (i8::MIN as i128, u8::MAX as i128),
            DataType::Int16 => (i16::MIN as i128, u16::MAX as i128),
            DataType::Int32 => (i32::MIN as i128, u32::MAX as i128),
            DataType::Int64 => (i64::MIN as i128, u64::MAX as i128),
            DataType::UInt8 => (i8::MIN as i128, u8::MAX as i128),
            DataType::UInt16 => (i16::MIN as i128, u16::MAX as i128),
            DataType::UInt32 => (i32::MIN as i128, u32::MAX as i128),
            DataType::UInt64 => (i64::MIN as i128, u64::MAX as i128),
            _ => return None,
        })
    }
}

impl fmt::Display for DataType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let text = match self {
            DataType::Bool => "bool",
            DataType::Int8 => "int8",
            DataType::Int16 => "int16",
            DataType::Int32 => "int32",
            DataType::Int64 => "int64",
            DataType::UInt8 => "unsigned_int8",
            DataType::UInt16 => "unsigned_int16",
            DataType::UInt32 => "unsigned_int32",
            DataType::UInt64 => "unsigned_int64",
            DataType::Half => "half",
            DataType::Float => "float",
            DataType::Double => "double",
            DataType::String => "string",
            DataType::Ref => "ref",
            DataType::Type => "type",
        };
        f.write_str(text)
    }
}

/// A structure name: `$global` or `%local`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Name {
    pub global: bool,
    pub identifier: String,
}

impl fmt::Display for Name {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}{}", if self.global { '$' } else { '%' }, self.identifier)
    }
}

/// A literal value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Bool(bool),
    Integer(i128),
    Float(f64),
    String(String),
    /// A reference; an empty list is `null`.
    Ref(Vec<Name>),
    Type(DataType),
}

impl Value {
    pub fn describe(&self) -> &'static str {
        match self {
            Value::Bool(_) => "a bool",
            Value::Integer(_) => "an integer",
            Value::Float(_) => "a float",
            Value::String(_) => "a string",
            Value::Ref(_) => "a reference",
            Value::Type(_) => "a type",
        }
    }

    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Float(value) => Some(*value),
            Value::Integer(value) => Some(*value as f64),
            _ => None,
        }
    }

    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::String(text) => Some(text),
            _ => None,
        }
    }
}

/// `key = value` in a structure's property list.
#[derive(Clone, Debug, PartialEq)]
pub struct Property {
    pub key: String,
    pub value: Value,
    pub position: TextPosition,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Structure {
    pub name: Option<Name>,
    pub position: TextPosition,
    pub body: StructureBody,
}

#[derive(Clone, Debug, PartialEq)]
pub enum StructureBody {
    Custom {
        identifier: String,
        properties: Vec<Property>,
        children: Vec<Structure>,
    },
    /// `values` is flat; with `array_size: Some(n)` it holds consecutive groups of `n`.
    Primitive {
        data_type: DataType,
        array_size: Option<u32>,
        values: Vec<Value>,
    },
}

impl Structure {
    pub fn identifier(&self) -> String {
        match &self.body {
            StructureBody::Custom { identifier, .. } => identifier.clone(),
            StructureBody::Primitive { data_type, .. } => data_type.to_string(),
        }
    }

    pub fn property(&self, key: &str) -> Option<&Property> {
        match &self.body {
            StructureBody::Custom { properties, .. } => properties.iter().find(|property| property.key == key),
            StructureBody::Primitive { .. } => None,
        }
    }

    pub fn children(&self) -> &[Structure] {
        match &self.body {
            StructureBody::Custom { children, .. } => children,
            StructureBody::Primitive { .. } => &[],
        }
    }
}

/// Parses a whole OpenDDL file.
pub fn parse(text: &str) -> Result<Vec<Structure>, OpenDdlError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut parser = Parser { lexer: Lexer { text, offset: 0 }, peeked: None, depth: 0 };
    let mut structures = Vec::new();
    loop {
        let token = parser.peek()?;
        if token.kind == TokenKind::End {
            return Ok(structures);
        }
        structures.push(parser.structure()?);
    }
}

#[derive(Clone, Debug, PartialEq)]
enum TokenKind {
    Identifier(String),
    Name(Name),
    /// A numeric literal, kept as text until its data type is known.
    Number(String),
    Char(i128),
    String(String),
    Punct(char),
    End,
}

#[derive(Clone, Debug)]
struct Token {
    kind: TokenKind,
    offset: usize,
}

struct Lexer<'a> {
    text: &'a str,
    offset: usize,
}

impl<'a> Lexer<'a> {
    fn error(&self, offset: usize, message: impl Into<String>) -> OpenDdlError {
        OpenDdlError { position: TextPosition::of_byte_offset(self.text, offset), message: message.into() }
    }

    fn rest(&self) -> &'a str {
        &self.text[self.offset..]
    }

    fn skip_trivia(&mut self) -> Result<(), OpenDdlError> {
        loop {
            let rest = self.rest();
            let trimmed = rest.trim_start();
            self.offset += rest.len() - trimmed.len();
            if trimmed.starts_with("//") {
                self.offset += trimmed.find('\n').unwrap_or(trimmed.len());
            } else if let Some(comment) = trimmed.strip_prefix("/*") {
                match comment.find("*/") {
                    Some(end) => self.offset += end + 4,
                    None => return Err(self.error(self.offset, "unterminated `/*` comment")),
                }
            } else {
                return Ok(());
            }
        }
    }

    fn next(&mut self) -> Result<Token, OpenDdlError> {
        self.skip_trivia()?;
        let start = self.offset;
        let rest = self.rest();
        let Some(first) = rest.chars().next() else {
            return Ok(Token { kind: TokenKind::End, offset: start });
        };
        let kind = match first {
            '{' | '}' | '[' | ']' | '(' | ')' | ',' | '=' | '*' | ':' => {
                self.offset += 1;
                TokenKind::Punct(first)
            }
            '$' | '%' => {
                self.offset += 1;
                let identifier = self
                    .identifier()
                    .ok_or_else(|| self.error(start, format!("`{first}` must be followed by a name")))?;
                TokenKind::Name(Name { global: first == '$', identifier })
            }
            '"' => TokenKind::String(self.string()?),
            '\'' => TokenKind::Char(self.char_literal()?),
            c if c.is_ascii_digit() || c == '.' || c == '-' || c == '+' => TokenKind::Number(self.number()?),
            c if c.is_ascii_alphabetic() || c == '_' => TokenKind::Identifier(self.identifier().unwrap_or_default()),
            other => return Err(self.error(start, format!("unexpected character `{}`", other.escape_debug()))),
        };
        Ok(Token { kind, offset: start })
    }

    fn identifier(&mut self) -> Option<String> {
        let rest = self.rest();
        let first = rest.chars().next()?;
        if !(first.is_ascii_alphabetic() || first == '_') {
            return None;
        }
        let length = rest.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(rest.len());
        self.offset += length;
        Some(rest[..length].to_string())
    }

    fn number(&mut self) -> Result<String, OpenDdlError> {
        let start = self.offset;
        let rest = self.rest();
        let bytes = rest.as_bytes();
        let mut length = 0;
        if matches!(bytes.first(), Some(b'-' | b'+')) {
            length += 1;
        }
        let body = &rest[length..];
        let is_prefixed = body.len() > 1
            && body.as_bytes()[0] == b'0'
            && matches!(body.as_bytes()[1], b'x' | b'X' | b'o' | b'O' | b'b' | b'B');
        if is_prefixed {
            length += 2;
            length +=
                rest[length..].find(|c: char| !(c.is_ascii_hexdigit() || c == '_')).unwrap_or(rest.len() - length);
        } else {
            let mut seen_exponent = false;
            while length < bytes.len() {
                let c = bytes[length];
                let sign_after_exponent =
                    (c == b'-' || c == b'+') && seen_exponent && matches!(bytes[length - 1], b'e' | b'E');
                if c.is_ascii_digit() || c == b'.' || c == b'_' || sign_after_exponent {
                    length += 1;
                } else if (c == b'e' || c == b'E') && !seen_exponent {
                    seen_exponent = true;
                    length += 1;
                } else {
                    break;
                }
            }
        }
        let text = &rest[..length];
        if !text.bytes().any(|c| c.is_ascii_digit()) {
            return Err(self.error(start, format!("`{}` is not a number", text.chars().next().unwrap_or(' '))));
        }
        if let Some(next) = rest[length..].chars().next() {
            if next.is_ascii_alphanumeric() || next == '_' {
                return Err(self.error(start + length, format!("unexpected `{next}` in a number")));
            }
        }
        self.offset += length;
        Ok(text.to_string())
    }

    fn escape(&mut self, quote_offset: usize) -> Result<char, OpenDdlError> {
        let at = self.offset;
        let mut chars = self.rest().chars();
        let Some(c) = chars.next() else {
            return Err(self.error(quote_offset, "unterminated string"));
        };
        self.offset += c.len_utf8();
        let simple = match c {
            '"' => Some('"'),
            '\'' => Some('\''),
            '?' => Some('?'),
            '\\' => Some('\\'),
            'a' => Some('\u{7}'),
            'b' => Some('\u{8}'),
            'f' => Some('\u{c}'),
            'n' => Some('\n'),
            'r' => Some('\r'),
            't' => Some('\t'),
            'v' => Some('\u{b}'),
            _ => None,
        };
        if let Some(simple) = simple {
            return Ok(simple);
        }
        let digits = match c {
            'x' => 2,
            'u' => 4,
            'U' => 6,
            _ => return Err(self.error(at - 1, format!("unknown escape `\\{}`", c.escape_debug()))),
        };
        let hex = self.rest().get(..digits).filter(|hex| hex.bytes().all(|b| b.is_ascii_hexdigit()));
        let Some(hex) = hex else {
            return Err(self.error(at - 1, format!("`\\{c}` needs {digits} hexadecimal digits")));
        };
        self.offset += digits;
        let code = u32::from_str_radix(hex, 16).unwrap_or(u32::MAX);
        char::from_u32(code).ok_or_else(|| self.error(at - 1, format!("`\\{c}{hex}` is not a Unicode scalar value")))
    }

    fn quoted(&mut self, quote: char) -> Result<String, OpenDdlError> {
        let start = self.offset;
        self.offset += 1;
        let mut text = String::new();
        loop {
            let Some(c) = self.rest().chars().next() else {
                return Err(self.error(start, "unterminated string"));
            };
            self.offset += c.len_utf8();
            match c {
                c if c == quote => return Ok(text),
                '\\' => text.push(self.escape(start)?),
                '\n' | '\r' => {
                    return Err(self.error(start, "unterminated string (line break before the closing quote)"))
                }
                c => text.push(c),
            }
        }
    }

    fn string(&mut self) -> Result<String, OpenDdlError> {
        let mut text = self.quoted('"')?;
        // Adjacent string literals concatenate.
        loop {
            let saved = self.offset;
            self.skip_trivia()?;
            if self.rest().starts_with('"') {
                text.push_str(&self.quoted('"')?);
            } else {
                self.offset = saved;
                return Ok(text);
            }
        }
    }

    fn char_literal(&mut self) -> Result<i128, OpenDdlError> {
        let start = self.offset;
        let text = self.quoted('\'')?;
        if text.is_empty() || text.chars().any(|c| c as u32 > 0x7f) {
            return Err(self.error(start, "a character literal holds one or more ASCII characters"));
        }
        Ok(text.bytes().fold(0i128, |value, byte| (value << 8) | byte as i128))
    }
}

/// How deeply structures may nest. Real files nest a few levels; the parser, and the tree's
/// drop, comparison and walkers, recurse once per level, so a bound keeps a hostile file from
/// overflowing the stack.
pub(crate) const MAX_NESTING: usize = 100;

struct Parser<'a> {
    lexer: Lexer<'a>,
    peeked: Option<Token>,
    /// Structures open around the one being parsed.
    depth: usize,
}

impl Parser<'_> {
    fn peek(&mut self) -> Result<Token, OpenDdlError> {
        if self.peeked.is_none() {
            self.peeked = Some(self.lexer.next()?);
        }
        Ok(self.peeked.clone().expect("just filled"))
    }

    fn next(&mut self) -> Result<Token, OpenDdlError> {
        let token = self.peek()?;
        self.peeked = None;
        Ok(token)
    }

    fn error(&self, offset: usize, message: impl Into<String>) -> OpenDdlError {
        self.lexer.error(offset, message)
    }

    fn expect(&mut self, punct: char, context: &str) -> Result<Token, OpenDdlError> {
        let token = self.next()?;
        if token.kind == TokenKind::Punct(punct) {
            Ok(token)
        } else {
            Err(self.error(token.offset, format!("expected `{punct}` {context}, found {}", describe(&token.kind))))
        }
    }

    fn eat(&mut self, punct: char) -> Result<bool, OpenDdlError> {
        if self.peek()?.kind == TokenKind::Punct(punct) {
            self.next()?;
            Ok(true)
        } else {
            Ok(false)
        }
    }

    fn optional_name(&mut self) -> Result<Option<Name>, OpenDdlError> {
        if let TokenKind::Name(name) = self.peek()?.kind {
            self.next()?;
            return Ok(Some(name));
        }
        Ok(None)
    }

    fn structure(&mut self) -> Result<Structure, OpenDdlError> {
        let token = self.next()?;
        let position = TextPosition::of_byte_offset(self.lexer.text, token.offset);
        let TokenKind::Identifier(identifier) = token.kind else {
            return Err(
                self.error(token.offset, format!("expected a structure identifier, found {}", describe(&token.kind)))
            );
        };
        if let Some(data_type) = DataType::from_identifier(&identifier) {
            return self.primitive(data_type, position);
        }
        let name = self.optional_name()?;
        let mut properties = Vec::new();
        if self.eat('(')? && !self.eat(')')? {
            loop {
                properties.push(self.property()?);
                if self.eat(')')? {
                    break;
                }
                self.expect(',', "between properties")?;
            }
        }
        let open = self.expect('{', &format!("to open the `{identifier}` structure"))?;
        if self.depth >= MAX_NESTING {
            return Err(
                self.error(open.offset, format!("structures nested too deeply (more than {MAX_NESTING} levels)"))
            );
        }
        self.depth += 1;
        let mut children = Vec::new();
        loop {
            let token = self.peek()?;
            match token.kind {
                TokenKind::Punct('}') => {
                    self.next()?;
                    break;
                }
                TokenKind::End => {
                    return Err(self.error(open.offset, format!("the `{{` of `{identifier}` is never closed")));
                }
                _ => children.push(self.structure()?),
            }
        }
        self.depth -= 1;
        Ok(Structure { name, position, body: StructureBody::Custom { identifier, properties, children } })
    }

    fn property(&mut self) -> Result<Property, OpenDdlError> {
        let token = self.next()?;
        let position = TextPosition::of_byte_offset(self.lexer.text, token.offset);
        let TokenKind::Identifier(key) = token.kind else {
            return Err(self.error(token.offset, format!("expected a property name, found {}", describe(&token.kind))));
        };
        // OpenDDL 3.0: a property without a value is a bool set to true.
        if !(self.eat('=')? || self.eat(':')?) {
            return Ok(Property { key, value: Value::Bool(true), position });
        }
        let token = self.next()?;
        let value = match token.kind {
            TokenKind::Identifier(ref word) if word == "true" || word == "false" => Value::Bool(word == "true"),
            TokenKind::Identifier(ref word) if word == "null" => Value::Ref(Vec::new()),
            TokenKind::Identifier(ref word) => match DataType::from_identifier(word) {
                Some(data_type) => Value::Type(data_type),
                None => return Err(self.error(token.offset, format!("`{word}` is not a property value"))),
            },
            TokenKind::String(text) => Value::String(text),
            TokenKind::Char(value) => Value::Integer(value),
            TokenKind::Number(ref text) => {
                number_value(text).ok_or_else(|| self.error(token.offset, format!("`{text}` is not a valid number")))?
            }
            TokenKind::Name(first) => Value::Ref(self.reference_rest(first)?),
            ref other => {
                return Err(self.error(token.offset, format!("expected a property value, found {}", describe(other))))
            }
        };
        Ok(Property { key, value, position })
    }

    fn reference_rest(&mut self, first: Name) -> Result<Vec<Name>, OpenDdlError> {
        let mut names = vec![first];
        while let TokenKind::Name(name) = self.peek()?.kind {
            if name.global {
                break;
            }
            self.next()?;
            names.push(name);
        }
        Ok(names)
    }

    fn primitive(&mut self, data_type: DataType, position: TextPosition) -> Result<Structure, OpenDdlError> {
        let mut array_size = None;
        if self.eat('[')? {
            let token = self.next()?;
            let size = match &token.kind {
                TokenKind::Number(text) => parse_integer(text).filter(|size| (1..=u32::MAX as i128).contains(size)),
                _ => None,
            };
            let Some(size) = size else {
                return Err(self
                    .error(token.offset, format!("expected a positive array size, found {}", describe(&token.kind))));
            };
            array_size = Some(size as u32);
            self.expect(']', "after the array size")?;
            self.eat('*')?; // state marker of OpenDDL 3.0 sub-arrays: accepted, no meaning here
        }
        let name = self.optional_name()?;
        let open = self.expect('{', &format!("to open the `{data_type}` data"))?;
        let mut values = Vec::new();
        if self.eat('}')? {
            return Ok(Structure { name, position, body: StructureBody::Primitive { data_type, array_size, values } });
        }
        loop {
            match array_size {
                None => values.push(self.literal(data_type)?),
                Some(size) => {
                    let sub_open = self.expect('{', &format!("to open a `{data_type}[{size}]` element"))?;
                    let mut count = 0;
                    loop {
                        values.push(self.literal(data_type)?);
                        count += 1;
                        if self.eat('}')? {
                            break;
                        }
                        self.expect(',', "between values")?;
                    }
                    if count != size {
                        return Err(self.error(
                            sub_open.offset,
                            format!("this element of `{data_type}[{size}]` has {count} values, expected {size}"),
                        ));
                    }
                }
            }
            if self.eat('}')? {
                break;
            }
            let token = self.peek()?;
            if token.kind == TokenKind::End {
                return Err(self.error(open.offset, format!("the `{{` of the `{data_type}` data is never closed")));
            }
            self.expect(',', "between values")?;
        }
        Ok(Structure { name, position, body: StructureBody::Primitive { data_type, array_size, values } })
    }

    fn literal(&mut self, data_type: DataType) -> Result<Value, OpenDdlError> {
        let token = self.next()?;
        let mismatch = |parser: &Self, found: &str| {
            parser.error(token.offset, format!("expected a {data_type} value, found {found}"))
        };
        match (data_type, &token.kind) {
            (DataType::Bool, TokenKind::Identifier(word)) if word == "true" || word == "false" => {
                Ok(Value::Bool(word == "true"))
            }
            (DataType::String, TokenKind::String(text)) => Ok(Value::String(text.clone())),
            (DataType::Ref, TokenKind::Identifier(word)) if word == "null" => Ok(Value::Ref(Vec::new())),
            (DataType::Ref, TokenKind::Name(first)) => Ok(Value::Ref(self.reference_rest(first.clone())?)),
            (DataType::Type, TokenKind::Identifier(word)) => {
                DataType::from_identifier(word).map(Value::Type).ok_or_else(|| mismatch(self, &format!("`{word}`")))
            }
            (DataType::Half | DataType::Float | DataType::Double, TokenKind::Number(text)) => {
                float_value(text, data_type)
                    .ok_or_else(|| self.error(token.offset, format!("`{text}` is not a valid {data_type}")))
            }
            (_, TokenKind::Number(text)) if data_type.integer_range().is_some() => {
                let (min, max) = data_type.integer_range().expect("checked");
                match parse_integer(text) {
                    Some(value) if (min..=max).contains(&value) => Ok(Value::Integer(value)),
                    Some(_) => Err(self.error(token.offset, format!("`{text}` does not fit in {data_type}"))),
                    None => Err(mismatch(self, &format!("`{text}`"))),
                }
            }
            (_, TokenKind::Char(value)) if data_type.integer_range().is_some() => Ok(Value::Integer(*value)),
            (_, other) => Err(mismatch(self, &describe(other))),
        }
    }
}

fn describe(kind: &TokenKind) -> String {
    match kind {
        TokenKind::Identifier(word) if word == "true" || word == "false" => {
            format!("the bool `{word}`")
        }
        TokenKind::Identifier(word) => format!("`{word}`"),
        TokenKind::Name(name) => format!("the name `{name}`"),
        TokenKind::Number(text) => format!("the number `{text}`"),
        TokenKind::Char(_) => "a character literal".to_string(),
        TokenKind::String(text) => format!("the string {text:?}"),
        TokenKind::Punct(c) => format!("`{c}`"),
        TokenKind::End => "the end of the file".to_string(),
    }
}

/// An integer literal in any base, with an optional sign and `_` separators.
fn parse_integer(text: &str) -> Option<i128> {
    let (negative, body) = match text.as_bytes().first() {
        Some(b'-') => (true, &text[1..]),
        Some(b'+') => (false, &text[1..]),
        _ => (false, text),
    };
    let body = body.replace('_', "");
    let (radix, digits) = match body.get(..2) {
        Some("0x" | "0X") => (16, &body[2..]),
        Some("0o" | "0O") => (8, &body[2..]),
        Some("0b" | "0B") => (2, &body[2..]),
        _ => (10, body.as_str()),
    };
    if digits.is_empty() {
        return None;
    }
    let magnitude = i128::from_str_radix(digits, radix).ok()?;
    Some(if negative { -magnitude } else { magnitude })
}

fn is_bit_pattern(text: &str) -> bool {
    let body = text.trim_start_matches(['-', '+']);
    matches!(body.get(..2), Some("0x" | "0X" | "0o" | "0O" | "0b" | "0B"))
}

/// A float literal; hex, octal and binary literals are the bit pattern of the float type.
fn float_value(text: &str, data_type: DataType) -> Option<Value> {
    if is_bit_pattern(text) {
        let bits = parse_integer(text)?;
        let value = match data_type {
            DataType::Half => half_to_f32(u16::try_from(bits).ok()?) as f64,
            DataType::Float => f32::from_bits(u32::try_from(bits).ok()?) as f64,
            _ => f64::from_bits(u64::try_from(bits).ok()?),
        };
        return Some(Value::Float(value));
    }
    text.replace('_', "").parse::<f64>().ok().map(Value::Float)
}

fn number_value(text: &str) -> Option<Value> {
    if is_bit_pattern(text) || !text.contains(['.', 'e', 'E']) {
        parse_integer(text).map(Value::Integer)
    } else {
        text.replace('_', "").parse::<f64>().ok().map(Value::Float)
    }
}

fn half_to_f32(bits: u16) -> f32 {
    let sign = if bits & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exponent = ((bits >> 10) & 0x1f) as i32;
    let mantissa = (bits & 0x3ff) as f32;
    sign * match exponent {
        0 => mantissa * 2f32.powi(-24),
        31 if mantissa == 0.0 => f32::INFINITY,
        31 => f32::NAN,
        _ => (1.0 + mantissa / 1024.0) * 2f32.powi(exponent - 15),
    }
}
