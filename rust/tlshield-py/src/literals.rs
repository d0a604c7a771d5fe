//! Literals as Python strings, one encoding everywhere: the formula's own text, `"g3"` for an
//! atom and `"!g3"` for its negation (as in `Automaton.edges()` guards).

use pyo3::prelude::*;
use pyo3::types::PyString;
use tlshield_core::cnf::Literal;

/// The text of every literal over a spec's atoms, made once and shared by each result.
pub struct LiteralNames {
    /// Per atom: (`"a"`, `"!a"`).
    names: Vec<(Py<PyString>, Py<PyString>)>,
}

impl LiteralNames {
    /// The names of the literals over `atoms`.
    pub fn new(py: Python<'_>, atoms: &[String]) -> Self {
        let names = atoms
            .iter()
            .map(|a| {
                (
                    PyString::new(py, a).unbind(),
                    PyString::new(py, &format!("!{a}")).unbind(),
                )
            })
            .collect();
        LiteralNames { names }
    }

    /// The text of `literal`.
    pub fn get<'py>(&self, py: Python<'py>, literal: &Literal) -> Bound<'py, PyString> {
        let (pos, neg) = &self.names[literal.atom];
        if literal.positive { pos } else { neg }.bind(py).clone()
    }
}
