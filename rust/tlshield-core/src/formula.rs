//! scTLTL formulas: the AST, a parser with column-accurate errors, the syntactic co-safety check
//! and canonical printing. `Spec` (module `spec`) binds a formula to the predicates of its atoms.
//!
//! Grammar, loosest to tightest: `->` (right-assoc) < `|` < `&` < `U` (right-assoc) < prefix
//! `!` `F` `X`; atoms `[a-z_][a-z0-9_]*`, constants `true` `false`, parentheses. The Spot/Lomap
//! spellings `&&` `||` `<>` `=>` are accepted too. A formula is scTLTL when `!` and the left side
//! of `->` only contain propositional subformulas; `G` (`[]`), `R` and `W` are rejected.

use std::fmt;

use crate::error::SpecError;

/// An scTLTL formula. Atoms are indices into the atom list of the `Spec` (or of
/// [`Formula::parse`]). `And`/`Or` are n-ary and never directly nest themselves.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Formula {
    /// Always true (robustness `+inf`).
    True,
    /// Always false (robustness `-inf`).
    False,
    /// An atomic proposition, by index.
    Atom(usize),
    /// Negation of a propositional subformula.
    Not(Box<Formula>),
    /// Conjunction (at least two operands).
    And(Vec<Formula>),
    /// Disjunction (at least two operands).
    Or(Vec<Formula>),
    /// `a -> b` with propositional `a`.
    Implies(Box<Formula>, Box<Formula>),
    /// `a U b` (strong until).
    Until(Box<Formula>, Box<Formula>),
    /// `F a` (eventually).
    Eventually(Box<Formula>),
    /// `X a` (strong next: false at the last state).
    Next(Box<Formula>),
}

/// How deep the parser may recurse; deeper input is rejected instead of exhausting the stack.
const MAX_DEPTH: usize = 128;

impl Formula {
    /// Parses `text`, returning the formula and its atom names in order of first appearance.
    pub fn parse(text: &str) -> Result<(Formula, Vec<String>), SpecError> {
        let tokens = tokenize(text)?;
        let mut parser = Parser {
            text,
            tokens,
            at: 0,
            depth: 0,
            atoms: Vec::new(),
        };
        let parsed = parser.implies()?;
        let (tok, column) = parser.peek();
        if *tok != Tok::End {
            return Err(SpecError::parse(
                text,
                column,
                format!(
                    "unexpected {} after a complete formula (missing an operator?)",
                    tok.describe()
                ),
            ));
        }
        Ok((parsed.formula, parser.atoms))
    }

    /// Whether the formula contains a temporal operator (`U`, `F`, `X`).
    pub fn is_temporal(&self) -> bool {
        match self {
            Formula::True | Formula::False | Formula::Atom(_) => false,
            Formula::Not(a) => a.is_temporal(),
            Formula::And(v) | Formula::Or(v) => v.iter().any(Formula::is_temporal),
            Formula::Implies(a, b) => a.is_temporal() || b.is_temporal(),
            Formula::Until(..) | Formula::Eventually(_) | Formula::Next(_) => true,
        }
    }

    /// A conjunction of `parts`, flattening nested conjunctions.
    pub fn and(parts: Vec<Formula>) -> Formula {
        Self::flatten(parts, true)
    }

    /// A disjunction of `parts`, flattening nested disjunctions.
    pub fn or(parts: Vec<Formula>) -> Formula {
        Self::flatten(parts, false)
    }

    fn flatten(parts: Vec<Formula>, conj: bool) -> Formula {
        let mut flat = Vec::with_capacity(parts.len());
        for p in parts {
            match p {
                Formula::And(v) if conj => flat.extend(v),
                Formula::Or(v) if !conj => flat.extend(v),
                other => flat.push(other),
            }
        }
        match flat.len() {
            0 if conj => Formula::True,
            0 => Formula::False,
            1 => flat.pop().expect("one element"),
            _ if conj => Formula::And(flat),
            _ => Formula::Or(flat),
        }
    }

    /// Displays the formula in canonical form with the given atom names.
    pub fn display<'a>(&'a self, atoms: &'a [String]) -> FormulaDisplay<'a> {
        FormulaDisplay {
            formula: self,
            atoms,
        }
    }

    /// Binding strength used for printing: binary operators print their binary operands in
    /// parentheses (except a right-nested `->`), unary operators and atoms bind tightest.
    fn is_binary(&self) -> bool {
        matches!(
            self,
            Formula::And(_) | Formula::Or(_) | Formula::Implies(..) | Formula::Until(..)
        )
    }
}

/// Canonical text of a [`Formula`] (see [`Formula::display`]).
pub struct FormulaDisplay<'a> {
    formula: &'a Formula,
    atoms: &'a [String],
}

impl FormulaDisplay<'_> {
    fn write(&self, f: &mut fmt::Formatter<'_>, node: &Formula) -> fmt::Result {
        match node {
            Formula::True => f.write_str("true"),
            Formula::False => f.write_str("false"),
            Formula::Atom(i) => match self.atoms.get(*i) {
                Some(name) => f.write_str(name),
                None => write!(f, "atom{i}"),
            },
            Formula::Not(a) => {
                f.write_str("!")?;
                self.operand(f, a)
            }
            Formula::Eventually(a) => {
                f.write_str("F ")?;
                self.operand(f, a)
            }
            Formula::Next(a) => {
                f.write_str("X ")?;
                self.operand(f, a)
            }
            Formula::And(v) | Formula::Or(v) => {
                let sep = if matches!(node, Formula::And(_)) {
                    " & "
                } else {
                    " | "
                };
                for (k, part) in v.iter().enumerate() {
                    if k > 0 {
                        f.write_str(sep)?;
                    }
                    self.operand(f, part)?;
                }
                Ok(())
            }
            Formula::Until(a, b) => {
                self.operand(f, a)?;
                f.write_str(" U ")?;
                self.operand(f, b)
            }
            Formula::Implies(a, b) => {
                self.operand(f, a)?;
                f.write_str(" -> ")?;
                if matches!(**b, Formula::Implies(..)) {
                    self.write(f, b)
                } else {
                    self.operand(f, b)
                }
            }
        }
    }

    fn operand(&self, f: &mut fmt::Formatter<'_>, node: &Formula) -> fmt::Result {
        if node.is_binary() {
            f.write_str("(")?;
            self.write(f, node)?;
            f.write_str(")")
        } else {
            self.write(f, node)
        }
    }
}

impl fmt::Display for FormulaDisplay<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.write(f, self.formula)
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    LParen,
    RParen,
    Not,
    And,
    Or,
    Implies,
    Until,
    Eventually,
    Next,
    /// An operator that is never co-safe; the string is its spelling.
    Forbidden(&'static str),
    True,
    False,
    Ident(String),
    End,
}

impl Tok {
    fn describe(&self) -> String {
        match self {
            Tok::LParen => "`(`".into(),
            Tok::RParen => "`)`".into(),
            Tok::Not => "`!`".into(),
            Tok::And => "`&`".into(),
            Tok::Or => "`|`".into(),
            Tok::Implies => "`->`".into(),
            Tok::Until => "`U`".into(),
            Tok::Eventually => "`F`".into(),
            Tok::Next => "`X`".into(),
            Tok::Forbidden(s) => format!("`{s}`"),
            Tok::True => "`true`".into(),
            Tok::False => "`false`".into(),
            Tok::Ident(name) => format!("atom `{name}`"),
            Tok::End => "end of formula".into(),
        }
    }
}

fn tokenize(text: &str) -> Result<Vec<(Tok, usize)>, SpecError> {
    let chars: Vec<char> = text.chars().collect();
    let mut tokens = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let column = i + 1;
        let next = chars.get(i + 1).copied();
        let (tok, width) = match (c, next) {
            (c, _) if c.is_whitespace() => {
                i += 1;
                continue;
            }
            ('(', _) => (Tok::LParen, 1),
            (')', _) => (Tok::RParen, 1),
            ('!', _) => (Tok::Not, 1),
            ('&', Some('&')) => (Tok::And, 2),
            ('&', _) => (Tok::And, 1),
            ('|', Some('|')) => (Tok::Or, 2),
            ('|', _) => (Tok::Or, 1),
            ('-', Some('>')) => (Tok::Implies, 2),
            ('=', Some('>')) => (Tok::Implies, 2),
            ('<', Some('>')) => (Tok::Eventually, 2),
            ('[', Some(']')) => (Tok::Forbidden("[]"), 2),
            ('U', _) => (Tok::Until, 1),
            ('F', _) => (Tok::Eventually, 1),
            ('X', _) => (Tok::Next, 1),
            ('G', _) => (Tok::Forbidden("G"), 1),
            ('R', _) => (Tok::Forbidden("R"), 1),
            ('W', _) => (Tok::Forbidden("W"), 1),
            (c, _) if c.is_ascii_lowercase() || c == '_' => {
                let len = chars[i..]
                    .iter()
                    .take_while(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || **c == '_')
                    .count();
                let word: String = chars[i..i + len].iter().collect();
                let tok = match word.as_str() {
                    "true" => Tok::True,
                    "false" => Tok::False,
                    _ => Tok::Ident(word),
                };
                (tok, len)
            }
            (c, _) => {
                let hint = if c.is_ascii_uppercase() || c.is_ascii_digit() {
                    " (atoms are lowercase: [a-z_][a-z0-9_]*; operators are ! & | -> U F X)"
                } else {
                    ""
                };
                return Err(SpecError::parse(
                    text,
                    column,
                    format!("unexpected character {c:?}{hint}"),
                ));
            }
        };
        tokens.push((tok, column));
        i += width;
    }
    tokens.push((Tok::End, chars.len() + 1));
    Ok(tokens)
}

/// A parsed subformula and the first temporal operator in it (for co-safety messages).
struct Parsed {
    formula: Formula,
    first_temporal: Option<(usize, &'static str)>,
}

impl Parsed {
    fn plain(formula: Formula) -> Self {
        Parsed {
            formula,
            first_temporal: None,
        }
    }
}

struct Parser<'t> {
    text: &'t str,
    tokens: Vec<(Tok, usize)>,
    at: usize,
    depth: usize,
    atoms: Vec<String>,
}

impl Parser<'_> {
    fn peek(&self) -> (&Tok, usize) {
        let (tok, column) = &self.tokens[self.at];
        (tok, *column)
    }

    fn bump(&mut self) -> (Tok, usize) {
        let item = self.tokens[self.at].clone();
        if item.0 != Tok::End {
            self.at += 1;
        }
        item
    }

    fn descend(&mut self) -> Result<(), SpecError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            let (_, column) = self.peek();
            return Err(SpecError::parse(
                self.text,
                column,
                format!("formula nests too deeply (more than {MAX_DEPTH} levels)"),
            ));
        }
        Ok(())
    }

    fn not_co_safe(&self, op_column: usize, inner: (usize, &str), context: &str) -> SpecError {
        let (column, op) = inner;
        SpecError::not_co_safe(
            self.text,
            column,
            format!(
                "`{op}` {context} (column {op_column}); scTLTL only allows propositional \
                 (temporal-free) formulas there, otherwise the formula is not syntactically co-safe"
            ),
        )
    }

    /// `implies := or ('->' implies)?`
    fn implies(&mut self) -> Result<Parsed, SpecError> {
        self.descend()?;
        let lhs = self.or()?;
        let result = if *self.peek().0 == Tok::Implies {
            let (_, column) = self.bump();
            if let Some(inner) = lhs.first_temporal {
                return Err(self.not_co_safe(column, inner, "on the left of `->`"));
            }
            let rhs = self.implies()?;
            Parsed {
                formula: Formula::Implies(Box::new(lhs.formula), Box::new(rhs.formula)),
                first_temporal: rhs.first_temporal,
            }
        } else {
            lhs
        };
        self.depth -= 1;
        Ok(result)
    }

    /// `or := and ('|' and)*` and `and := until ('&' until)*`
    fn or(&mut self) -> Result<Parsed, SpecError> {
        self.nary(Tok::Or)
    }

    fn nary(&mut self, op: Tok) -> Result<Parsed, SpecError> {
        let operand = |p: &mut Self| {
            if op == Tok::Or {
                p.nary(Tok::And)
            } else {
                p.until()
            }
        };
        let first = operand(self)?;
        if *self.peek().0 != op {
            return Ok(first);
        }
        let mut first_temporal = first.first_temporal;
        let mut parts = vec![first.formula];
        while *self.peek().0 == op {
            self.bump();
            let next = operand(self)?;
            first_temporal = first_temporal.or(next.first_temporal);
            parts.push(next.formula);
        }
        let formula = if op == Tok::Or {
            Formula::or(parts)
        } else {
            Formula::and(parts)
        };
        Ok(Parsed {
            formula,
            first_temporal,
        })
    }

    fn forbidden(&self, column: usize, op: &str) -> SpecError {
        let name = match op {
            "R" => "release",
            "W" => "weak until",
            _ => "always",
        };
        SpecError::not_co_safe(
            self.text,
            column,
            format!(
                "`{op}` ({name}) is not allowed: scTLTL formulas must be syntactically co-safe \
                 (no always/release); use F, U and X"
            ),
        )
    }

    /// `until := unary ('U' until)?`
    fn until(&mut self) -> Result<Parsed, SpecError> {
        let lhs = self.unary()?;
        if let (Tok::Forbidden(op), column) = self.peek() {
            return Err(self.forbidden(column, op));
        }
        if *self.peek().0 != Tok::Until {
            return Ok(lhs);
        }
        let (_, column) = self.bump();
        self.descend()?;
        let rhs = self.until()?;
        self.depth -= 1;
        Ok(Parsed {
            formula: Formula::Until(Box::new(lhs.formula), Box::new(rhs.formula)),
            first_temporal: Some((column, "U")),
        })
    }

    /// `unary := ('!' | 'F' | 'X') unary | primary`
    fn unary(&mut self) -> Result<Parsed, SpecError> {
        let (tok, column) = self.peek();
        let tok = tok.clone();
        match tok {
            Tok::Not | Tok::Eventually | Tok::Next => {
                self.bump();
                self.descend()?;
                let inner = self.unary()?;
                self.depth -= 1;
                let boxed = Box::new(inner.formula);
                Ok(match tok {
                    Tok::Not => {
                        if let Some(t) = inner.first_temporal {
                            return Err(self.not_co_safe(column, t, "under the negation `!`"));
                        }
                        Parsed::plain(Formula::Not(boxed))
                    }
                    Tok::Eventually => Parsed {
                        formula: Formula::Eventually(boxed),
                        first_temporal: Some((column, "F")),
                    },
                    _ => Parsed {
                        formula: Formula::Next(boxed),
                        first_temporal: Some((column, "X")),
                    },
                })
            }
            Tok::Forbidden(op) => Err(self.forbidden(column, op)),
            _ => self.primary(),
        }
    }

    /// `primary := atom | 'true' | 'false' | '(' implies ')'`
    fn primary(&mut self) -> Result<Parsed, SpecError> {
        let (tok, column) = self.bump();
        match tok {
            Tok::True => Ok(Parsed::plain(Formula::True)),
            Tok::False => Ok(Parsed::plain(Formula::False)),
            Tok::Ident(name) => {
                let index = match self.atoms.iter().position(|a| *a == name) {
                    Some(i) => i,
                    None => {
                        self.atoms.push(name);
                        self.atoms.len() - 1
                    }
                };
                Ok(Parsed::plain(Formula::Atom(index)))
            }
            Tok::LParen => {
                let inner = self.implies()?;
                let (close, close_column) = self.bump();
                if close != Tok::RParen {
                    return Err(SpecError::parse(
                        self.text,
                        close_column,
                        format!(
                            "expected `)` to close the `(` at column {column}, found {}",
                            close.describe()
                        ),
                    ));
                }
                Ok(inner)
            }
            other => Err(SpecError::parse(
                self.text,
                column,
                format!(
                    "expected an atom, `true`, `false`, `(` or a prefix operator (`!`, `F`, `X`), \
                     found {}",
                    other.describe()
                ),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn canon(text: &str) -> String {
        let (f, atoms) = Formula::parse(text).unwrap();
        f.display(&atoms).to_string()
    }

    #[test]
    fn paper_task_round_trips() {
        let task = "(F g1 | F g2) & F g3 & (!g3 U (g1 | g2)) & ((c1 & c2) U g3)";
        assert_eq!(canon(task), task);
        let (_, atoms) = Formula::parse(task).unwrap();
        assert_eq!(atoms, ["g1", "g2", "g3", "c1", "c2"]);
    }

    #[test]
    fn precedence_and_associativity() {
        assert_eq!(canon("a | b & c"), "a | (b & c)");
        assert_eq!(canon("a & b U c"), "a & (b U c)");
        assert_eq!(canon("a U b U c"), "a U (b U c)");
        assert_eq!(canon("(a U b) U c"), "(a U b) U c");
        assert_eq!(canon("a -> b -> c"), "a -> b -> c");
        assert_eq!(canon("(a -> b) -> c"), "(a -> b) -> c");
        assert_eq!(canon("!a U F b"), "!a U F b");
        assert_eq!(canon("F a U b"), "F a U b");
        assert_eq!(canon("a & (b & c)"), "a & b & c");
        assert_eq!(canon("X X true"), "X X true");
    }

    #[test]
    fn spot_spellings() {
        assert_eq!(canon("c => <> a && b || d"), "c -> ((F a & b) | d)");
        assert_eq!(canon("Fa&Xb"), "F a & X b");
    }

    #[test]
    fn parse_errors_name_the_column() {
        let err = Formula::parse("F a & ").unwrap_err();
        assert!(matches!(err, SpecError::Parse { column: 7, .. }), "{err}");
        assert!(err.to_string().contains("found end of formula"), "{err}");
        let err = Formula::parse("(a | b").unwrap_err();
        assert!(
            err.to_string().contains("close the `(` at column 1"),
            "{err}"
        );
        let err = Formula::parse("a b").unwrap_err();
        assert!(matches!(err, SpecError::Parse { column: 3, .. }), "{err}");
        let err = Formula::parse("a & Bad").unwrap_err();
        assert!(matches!(err, SpecError::Parse { column: 5, .. }), "{err}");
        crate::tests_support::assert_error(Formula::parse(""), "Parse", "column 1");
        crate::tests_support::assert_error(Formula::parse("a & é"), "Parse", "column 5");
    }

    #[test]
    fn non_co_safe_formulas_are_rejected_with_column() {
        for (text, column) in [
            ("G a", 1),
            ("a & [] b", 5),
            ("!F a", 2),
            ("(F a) -> b", 2),
            ("a R b", 3),
            ("!(a & X b)", 7),
            ("F a -> b", 1),
        ] {
            match Formula::parse(text) {
                Err(SpecError::NotCoSafe { column: c, .. }) => assert_eq!(c, column, "{text}"),
                other => panic!("{text}: {other:?}"),
            }
        }
        assert!(Formula::parse("a -> F b").is_ok());
        assert!(Formula::parse("!(a & b) U c").is_ok());
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        let deep = format!("{}a{}", "(".repeat(100_000), ")".repeat(100_000));
        crate::tests_support::assert_error(Formula::parse(&deep), "Parse", "column 129");
        let bangs = format!("{}a", "!".repeat(100_000));
        crate::tests_support::assert_error(Formula::parse(&bangs), "Parse", "column 129");
        let untils = vec!["a"; 100_000].join(" U ");
        crate::tests_support::assert_error(Formula::parse(&untils), "Parse", "column 513");
        let ok = format!("{}a{}", "(".repeat(100), ")".repeat(100));
        assert!(Formula::parse(&ok).is_ok());
    }
}
