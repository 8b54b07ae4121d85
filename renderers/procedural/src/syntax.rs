//! Lexer and parser for the scene language (an ExprTk subset).
//!
//! Grammar, lowest precedence first:
//!
//! ```text
//! program    := statement (';' statement)* ';'?
//! statement  := 'var' NAME ('[' NUMBER ']')? (':=' (expr | '{' expr (',' expr)* '}'))?
//!             | 'if' '(' expr ')' body (';'? 'else' (if | body))?
//!             | 'while' '(' expr ')' body
//!             | 'for' '(' statement? ';' expr? ';' expr? ')' body
//!             | 'break' | 'continue' | '{' program '}' | expr
//! body       := '{' program '}' | statement
//! expr       := lvalue (':=' | '+=' | '-=' | '*=' | '/=' | '%=') expr | ternary
//! ternary    := or ('?' expr ':' expr)?
//! or         := and (('or' | '|' | 'nor' | 'xor') and)*
//! and        := cmp (('and' | '&' | 'nand') cmp)*
//! cmp        := sum (('<' | '<=' | '>' | '>=' | '==' | '=' | '!=' | '<>') sum)?
//! sum        := product (('+' | '-') product)*
//! product    := unary (('*' | '/' | '%') unary)*
//! unary      := ('-' | '+' | 'not') unary | power
//! power      := atom ('^' unary)?            (right-associative: 2^3^2 = 512; -2^2 = -4)
//! atom       := NUMBER | NAME | NAME '[' expr ']' | NAME '(' args ')' | '(' expr ')'
//! ```

use std::fmt;

/// A position in the source: 1-based line and column, and byte offset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Pos {
    /// Line, from 1.
    pub line: u32,
    /// Column, from 1 (in characters).
    pub col: u32,
    /// Byte offset in the source.
    pub offset: usize,
}

/// A syntax or semantic error at a position.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceError {
    /// Where.
    pub pos: Pos,
    /// What.
    pub message: String,
}

impl SourceError {
    /// An error at `pos`.
    pub fn new(pos: Pos, message: impl Into<String>) -> Self {
        SourceError { pos, message: message.into() }
    }

    /// `file:line:col: message`, the source line and a caret under the column.
    pub fn render(&self, file: &str, source: &str) -> String {
        let line = source.lines().nth(self.pos.line.saturating_sub(1) as usize).unwrap_or("");
        let caret = " ".repeat(self.pos.col.saturating_sub(1) as usize);
        format!("{file}:{}:{}: {}\n    {line}\n    {caret}^", self.pos.line, self.pos.col, self.message)
    }
}

impl fmt::Display for SourceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}: {}", self.pos.line, self.pos.col, self.message)
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Name(String),
    Sym(&'static str),
    End,
}

impl fmt::Display for Tok {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Tok::Num(n) => write!(f, "number {n}"),
            Tok::Name(n) => write!(f, "'{n}'"),
            Tok::Sym(s) => write!(f, "'{s}'"),
            Tok::End => write!(f, "end of program"),
        }
    }
}

const SYMBOLS: &[&str] = &[
    ":=", "+=", "-=", "*=", "/=", "%=", "<=", ">=", "==", "!=", "<>", "(", ")", "[", "]", "{", "}", ",", ";", "?", ":",
    "+", "-", "*", "/", "%", "^", "<", ">", "=", "&", "|",
];

fn lex(source: &str, start: Pos) -> Result<Vec<(Tok, Pos)>, SourceError> {
    let mut tokens = Vec::new();
    let bytes = source.as_bytes();
    let (mut i, mut line, mut col) = (0usize, start.line, start.col);
    let pos = |i: usize, line: u32, col: u32| Pos { line, col, offset: start.offset + i };
    while i < bytes.len() {
        let c = bytes[i];
        let here = pos(i, line, col);
        if c == b'\n' {
            i += 1;
            line += 1;
            col = 1;
            continue;
        }
        if c.is_ascii_whitespace() {
            i += 1;
            col += 1;
            continue;
        }
        // Comments: `// …` and `/* … */` as in ExprTk.
        if source[i..].starts_with("//") {
            while i < bytes.len() && bytes[i] != b'\n' {
                i += 1;
            }
            continue;
        }
        if source[i..].starts_with("/*") {
            let end = source[i + 2..].find("*/").ok_or_else(|| SourceError::new(here, "unterminated comment"))?;
            for ch in source[i..i + 2 + end + 2].chars() {
                if ch == '\n' {
                    line += 1;
                    col = 1;
                } else {
                    col += 1;
                }
            }
            i += 2 + end + 2;
            continue;
        }
        if c.is_ascii_digit() || (c == b'.' && bytes.get(i + 1).is_some_and(u8::is_ascii_digit)) {
            let s = i;
            while i < bytes.len() && (bytes[i].is_ascii_digit() || bytes[i] == b'.') {
                i += 1;
            }
            if i < bytes.len() && (bytes[i] == b'e' || bytes[i] == b'E') {
                let mut j = i + 1;
                if j < bytes.len() && (bytes[j] == b'+' || bytes[j] == b'-') {
                    j += 1;
                }
                if j < bytes.len() && bytes[j].is_ascii_digit() {
                    i = j;
                    while i < bytes.len() && bytes[i].is_ascii_digit() {
                        i += 1;
                    }
                }
            }
            let text = &source[s..i];
            let value =
                text.parse::<f64>().map_err(|_| SourceError::new(here, format!("malformed number '{text}'")))?;
            tokens.push((Tok::Num(value), here));
            col += (i - s) as u32;
            continue;
        }
        if c.is_ascii_alphabetic() || c == b'_' {
            let s = i;
            while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
                i += 1;
            }
            tokens.push((Tok::Name(source[s..i].to_string()), here));
            col += (i - s) as u32;
            continue;
        }
        match SYMBOLS.iter().find(|s| source[i..].starts_with(**s)) {
            Some(sym) => {
                tokens.push((Tok::Sym(sym), here));
                i += sym.len();
                col += sym.len() as u32;
            }
            None => {
                let ch = source[i..].chars().next().unwrap();
                return Err(SourceError::new(here, format!("unexpected character '{ch}'")));
            }
        }
    }
    tokens.push((Tok::End, pos(i, line, col)));
    Ok(tokens)
}

/// Binary operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(missing_docs)]
pub enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    Mod,
    Pow,
    Lt,
    Le,
    Gt,
    Ge,
    Eq,
    Ne,
    And,
    Or,
    Xor,
    Nand,
    Nor,
}

/// Compound assignment operators (`:=` is `None`).
pub type AssignOp = Option<BinOp>;

/// A parsed expression.
#[derive(Debug, Clone, PartialEq)]
#[allow(missing_docs)]
pub enum Expr {
    Num(f64),
    Name(String, Pos),
    Index(String, Box<Expr>, Pos),
    Call(String, Vec<Expr>, Pos),
    Neg(Box<Expr>),
    Not(Box<Expr>),
    Binary(BinOp, Box<Expr>, Box<Expr>),
    Ternary(Box<Expr>, Box<Expr>, Box<Expr>),
    Assign { target: Box<Expr>, op: AssignOp, value: Box<Expr>, pos: Pos },
}

/// A parsed statement.
#[derive(Debug, Clone, PartialEq)]
#[allow(missing_docs)]
pub enum Stmt {
    Var { name: String, size: Option<usize>, init: Vec<Expr>, pos: Pos },
    Expr(Expr),
    If { cond: Expr, then: Vec<Stmt>, otherwise: Vec<Stmt> },
    While { cond: Expr, body: Vec<Stmt>, step: Option<Expr>, pos: Pos },
    Block(Vec<Stmt>),
    Break(Pos),
    Continue(Pos),
}

struct Parser {
    tokens: Vec<(Tok, Pos)>,
    at: usize,
}

/// Parses a program whose text starts at `start` in its file.
pub fn parse_program(source: &str, start: Pos) -> Result<Vec<Stmt>, SourceError> {
    let mut p = Parser { tokens: lex(source, start)?, at: 0 };
    let stmts = p.statements(&Tok::End)?;
    p.expect_end()?;
    Ok(stmts)
}

impl Parser {
    fn peek(&self) -> &Tok {
        &self.tokens[self.at].0
    }
    fn pos(&self) -> Pos {
        self.tokens[self.at].1
    }
    fn bump(&mut self) -> (Tok, Pos) {
        let t = self.tokens[self.at].clone();
        if self.at + 1 < self.tokens.len() {
            self.at += 1;
        }
        t
    }
    fn is_sym(&self, s: &str) -> bool {
        matches!(self.peek(), Tok::Sym(x) if *x == s)
    }
    fn is_word(&self, w: &str) -> bool {
        matches!(self.peek(), Tok::Name(x) if x == w)
    }
    fn eat_sym(&mut self, s: &str) -> bool {
        let yes = self.is_sym(s);
        if yes {
            self.bump();
        }
        yes
    }
    fn expect_sym(&mut self, s: &str) -> Result<Pos, SourceError> {
        if self.is_sym(s) {
            Ok(self.bump().1)
        } else {
            Err(SourceError::new(self.pos(), format!("expected '{s}' but found {}", self.peek())))
        }
    }
    fn expect_end(&self) -> Result<(), SourceError> {
        match self.peek() {
            Tok::End => Ok(()),
            t => Err(SourceError::new(self.pos(), format!("expected ';' or end of program but found {t}"))),
        }
    }

    /// Statements separated by ';' until `end` (not consumed).
    fn statements(&mut self, end: &Tok) -> Result<Vec<Stmt>, SourceError> {
        let mut out = Vec::new();
        loop {
            while self.eat_sym(";") {}
            if self.peek() == end || matches!(self.peek(), Tok::End) {
                return Ok(out);
            }
            out.push(self.statement()?);
            // A statement ends at ';', or right after a closing brace.
            let after_brace = self.at > 0 && self.tokens[self.at - 1].0 == Tok::Sym("}");
            if !self.eat_sym(";") && !after_brace && self.peek() != end {
                return Err(SourceError::new(self.pos(), format!("expected ';' but found {}", self.peek())));
            }
        }
    }

    fn body(&mut self) -> Result<Vec<Stmt>, SourceError> {
        if self.eat_sym("{") {
            let stmts = self.statements(&Tok::Sym("}"))?;
            self.expect_sym("}")?;
            Ok(stmts)
        } else {
            Ok(vec![self.statement()?])
        }
    }

    fn statement(&mut self) -> Result<Stmt, SourceError> {
        let pos = self.pos();
        if self.eat_sym("{") {
            let stmts = self.statements(&Tok::Sym("}"))?;
            self.expect_sym("}")?;
            return Ok(Stmt::Block(stmts));
        }
        let Tok::Name(word) = self.peek().clone() else {
            return Ok(Stmt::Expr(self.expr()?));
        };
        match word.as_str() {
            "var" => {
                self.bump();
                let (name, npos) = match self.bump() {
                    (Tok::Name(n), p) => (n, p),
                    (t, p) => {
                        return Err(SourceError::new(p, format!("expected a variable name after 'var' but found {t}")))
                    }
                };
                let size = if self.eat_sym("[") {
                    let size = match self.bump() {
                        (Tok::Num(n), _) if n >= 1.0 && n.fract() == 0.0 && n <= 1e6 => n as usize,
                        (t, p) => {
                            return Err(SourceError::new(
                                p,
                                format!("array size must be a whole number ≥ 1, found {t}"),
                            ))
                        }
                    };
                    self.expect_sym("]")?;
                    Some(size)
                } else {
                    None
                };
                let mut init = Vec::new();
                if self.eat_sym(":=") {
                    if size.is_some() && self.eat_sym("{") {
                        loop {
                            init.push(self.expr()?);
                            if !self.eat_sym(",") {
                                break;
                            }
                        }
                        self.expect_sym("}")?;
                    } else {
                        init.push(self.expr()?);
                    }
                }
                if let Some(n) = size {
                    if init.len() > n {
                        return Err(SourceError::new(
                            npos,
                            format!("array '{name}' has {n} elements but {} initial values", init.len()),
                        ));
                    }
                }
                Ok(Stmt::Var { name, size, init, pos: npos })
            }
            "if" if self.tokens.get(self.at + 1).is_some_and(|t| t.0 == Tok::Sym("(")) && !self.if_is_function() => {
                self.bump();
                self.expect_sym("(")?;
                let cond = self.expr()?;
                self.expect_sym(")")?;
                let then = self.body()?;
                // `if (c) x := 1; else x := 2;` — a ';' may precede 'else'.
                let save = self.at;
                self.eat_sym(";");
                let otherwise = if self.is_word("else") {
                    self.bump();
                    self.body()?
                } else {
                    self.at = save;
                    Vec::new()
                };
                Ok(Stmt::If { cond, then, otherwise })
            }
            "while" => {
                self.bump();
                self.expect_sym("(")?;
                let cond = self.expr()?;
                self.expect_sym(")")?;
                Ok(Stmt::While { cond, body: self.body()?, step: None, pos })
            }
            "for" => {
                self.bump();
                self.expect_sym("(")?;
                let init = if self.is_sym(";") { None } else { Some(self.statement()?) };
                self.expect_sym(";")?;
                let cond = if self.is_sym(";") { Expr::Num(1.0) } else { self.expr()? };
                self.expect_sym(";")?;
                let step = if self.is_sym(")") { None } else { Some(self.expr()?) };
                self.expect_sym(")")?;
                let body = self.body()?;
                let looped = Stmt::While { cond, body, step, pos };
                Ok(Stmt::Block(init.into_iter().chain([looped]).collect()))
            }
            "break" => {
                self.bump();
                Ok(Stmt::Break(pos))
            }
            "continue" => {
                self.bump();
                Ok(Stmt::Continue(pos))
            }
            "else" => Err(SourceError::new(pos, "'else' without 'if'")),
            _ => Ok(Stmt::Expr(self.expr()?)),
        }
    }

    /// `if(c, a, b)` is ExprTk's function form: three comma-separated arguments.
    fn if_is_function(&self) -> bool {
        let mut depth = 0;
        for (t, _) in &self.tokens[self.at + 1..] {
            match t {
                Tok::Sym("(") | Tok::Sym("[") | Tok::Sym("{") => depth += 1,
                Tok::Sym(")") | Tok::Sym("]") | Tok::Sym("}") => {
                    depth -= 1;
                    if depth == 0 {
                        return false;
                    }
                }
                Tok::Sym(",") if depth == 1 => return true,
                Tok::End => return false,
                _ => {}
            }
        }
        false
    }

    fn expr(&mut self) -> Result<Expr, SourceError> {
        let pos = self.pos();
        let lhs = self.ternary()?;
        let op = match self.peek() {
            Tok::Sym(":=") => None,
            Tok::Sym("+=") => Some(BinOp::Add),
            Tok::Sym("-=") => Some(BinOp::Sub),
            Tok::Sym("*=") => Some(BinOp::Mul),
            Tok::Sym("/=") => Some(BinOp::Div),
            Tok::Sym("%=") => Some(BinOp::Mod),
            _ => return Ok(lhs),
        };
        let apos = self.bump().1;
        if !matches!(lhs, Expr::Name(..) | Expr::Index(..)) {
            return Err(SourceError::new(apos, "only a variable, array element or feature can be assigned to"));
        }
        let value = self.expr()?;
        let _ = pos;
        Ok(Expr::Assign { target: Box::new(lhs), op, value: Box::new(value), pos: apos })
    }

    fn ternary(&mut self) -> Result<Expr, SourceError> {
        let cond = self.or()?;
        if self.eat_sym("?") {
            let a = self.expr()?;
            self.expect_sym(":")?;
            let b = self.expr()?;
            return Ok(Expr::Ternary(Box::new(cond), Box::new(a), Box::new(b)));
        }
        Ok(cond)
    }

    fn binary_level(
        &mut self,
        next: fn(&mut Self) -> Result<Expr, SourceError>,
        ops: &[(&str, BinOp)],
    ) -> Result<Expr, SourceError> {
        let mut lhs = next(self)?;
        loop {
            let op = ops.iter().find(|(w, _)| self.is_sym(w) || self.is_word(w)).map(|(_, op)| *op);
            let Some(op) = op else { return Ok(lhs) };
            self.bump();
            let rhs = next(self)?;
            lhs = Expr::Binary(op, Box::new(lhs), Box::new(rhs));
        }
    }

    fn or(&mut self) -> Result<Expr, SourceError> {
        self.binary_level(Self::and, &[("or", BinOp::Or), ("|", BinOp::Or), ("xor", BinOp::Xor), ("nor", BinOp::Nor)])
    }
    fn and(&mut self) -> Result<Expr, SourceError> {
        self.binary_level(Self::cmp, &[("and", BinOp::And), ("&", BinOp::And), ("nand", BinOp::Nand)])
    }
    fn cmp(&mut self) -> Result<Expr, SourceError> {
        self.binary_level(
            Self::sum,
            &[
                ("<=", BinOp::Le),
                (">=", BinOp::Ge),
                ("<>", BinOp::Ne),
                ("<", BinOp::Lt),
                (">", BinOp::Gt),
                ("==", BinOp::Eq),
                ("=", BinOp::Eq),
                ("!=", BinOp::Ne),
            ],
        )
    }
    fn sum(&mut self) -> Result<Expr, SourceError> {
        self.binary_level(Self::product, &[("+", BinOp::Add), ("-", BinOp::Sub)])
    }
    fn product(&mut self) -> Result<Expr, SourceError> {
        self.binary_level(Self::unary, &[("*", BinOp::Mul), ("/", BinOp::Div), ("%", BinOp::Mod)])
    }
    fn unary(&mut self) -> Result<Expr, SourceError> {
        if self.eat_sym("-") {
            return Ok(Expr::Neg(Box::new(self.unary()?)));
        }
        if self.eat_sym("+") {
            return self.unary();
        }
        if self.is_word("not") && !self.tokens.get(self.at + 1).is_some_and(|t| t.0 == Tok::Sym("(")) {
            self.bump();
            return Ok(Expr::Not(Box::new(self.unary()?)));
        }
        self.power()
    }
    fn power(&mut self) -> Result<Expr, SourceError> {
        let base = self.atom()?;
        if self.eat_sym("^") {
            let exponent = self.unary()?;
            return Ok(Expr::Binary(BinOp::Pow, Box::new(base), Box::new(exponent)));
        }
        Ok(base)
    }

    fn atom(&mut self) -> Result<Expr, SourceError> {
        let (tok, pos) = self.bump();
        match tok {
            Tok::Num(n) => Ok(Expr::Num(n)),
            Tok::Sym("(") => {
                let e = self.expr()?;
                self.expect_sym(")")?;
                Ok(e)
            }
            Tok::Name(name) if self.is_sym("(") => {
                self.bump();
                let mut args = Vec::new();
                if !self.is_sym(")") {
                    loop {
                        args.push(self.expr()?);
                        if !self.eat_sym(",") {
                            break;
                        }
                    }
                }
                self.expect_sym(")")?;
                Ok(Expr::Call(name, args, pos))
            }
            Tok::Name(name) if self.is_sym("[") => {
                self.bump();
                let index = self.expr()?;
                self.expect_sym("]")?;
                Ok(Expr::Index(name, Box::new(index), pos))
            }
            Tok::Name(name) => Ok(Expr::Name(name, pos)),
            t => Err(SourceError::new(pos, format!("expected a value but found {t}"))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<Vec<Stmt>, SourceError> {
        parse_program(s, Pos { line: 1, col: 1, offset: 0 })
    }

    #[test]
    fn precedence_and_associativity() {
        let e = |s: &str| match parse(s).unwrap().remove(0) {
            Stmt::Expr(e) => e,
            other => panic!("{other:?}"),
        };
        use BinOp::*;
        let n = |x: f64| Box::new(Expr::Num(x));
        assert_eq!(e("1 + 2 * 3"), Expr::Binary(Add, n(1.0), Box::new(Expr::Binary(Mul, n(2.0), n(3.0)))));
        assert_eq!(e("2 ^ 3 ^ 2"), Expr::Binary(Pow, n(2.0), Box::new(Expr::Binary(Pow, n(3.0), n(2.0)))));
        assert_eq!(e("-2 ^ 2"), Expr::Neg(Box::new(Expr::Binary(Pow, n(2.0), n(2.0)))));
        assert!(matches!(e("1 < 2 and 3 > 2 or 0"), Expr::Binary(Or, _, _)));
        assert!(matches!(e("1 ? 2 : 3"), Expr::Ternary(..)));
    }

    #[test]
    fn errors_point_at_the_offending_token() {
        let err = parse("var x := 1;\nvar y := (x + 2;\n").unwrap_err();
        assert_eq!((err.pos.line, err.pos.col), (2, 16));
        assert_eq!(err.message, "expected ')' but found ';'");
        let shown = err.render("s.expr", "var x := 1;\nvar y := (x + 2;\n");
        assert!(shown.starts_with("s.expr:2:16: expected ')'"), "{shown}");
        assert!(shown.ends_with("    var y := (x + 2;\n                   ^"), "{shown}");
        assert_eq!(parse("x := 1 $ 2").unwrap_err().message, "unexpected character '$'");
        assert_eq!(
            parse("1 := 2").unwrap_err().message,
            "only a variable, array element or feature can be assigned to"
        );
        assert!(parse("x := 1 y := 2").unwrap_err().message.contains("expected ';'"));
        // An if without braces ends at ';' like any statement (it swallowed the next one).
        assert!(parse("if (c) x := 1 y := 2").unwrap_err().message.contains("expected ';'"));
        assert!(parse("if (c) { x := 1 } y := 2").is_ok());
    }

    #[test]
    fn control_flow_forms() {
        assert!(
            matches!(&parse("if (x) y := 1; else y := 2;").unwrap()[0], Stmt::If { otherwise, .. } if otherwise.len() == 1)
        );
        assert!(matches!(
            &parse("if (x) { y := 1 } else if (z) { y := 2 } else { y := 3 }").unwrap()[0],
            Stmt::If { .. }
        ));
        assert!(matches!(&parse("y := if(x, 1, 2)").unwrap()[0], Stmt::Expr(Expr::Assign { .. })));
        assert!(
            matches!(&parse("for (var i := 0; i < 3; i += 1) { x += i; }").unwrap()[0], Stmt::Block(b) if b.len() == 2)
        );
        assert_eq!(parse("while (1) { break; continue; }").unwrap().len(), 1);
        assert_eq!(parse("// c\n/* d\n */ x := 1 // e").unwrap().len(), 1);
    }
}
