//! The declared order in which barriers give way when the QP cannot hold them all
//! ([`ShieldParams::give_way`]). The relaxed problem is solved with slack on the rows of the
//! first-named barriers only; if that is infeasible too, on those and the next-named; and so
//! on, the barriers not named last (all together). A row gives way only when every row named
//! before it could not restore feasibility alone. Within one level the slack weights still
//! share the give-way. With nothing named every row is in one level: one relaxed solve.

use super::{BarrierSource, ShieldError, ShieldParams};
use crate::spec::Spec;

/// Each barrier's give-way level (0 gives way first).
#[derive(Debug, Clone, Default)]
pub(super) struct GiveWay {
    /// Per user barrier, in the order of [`ShieldParams::barriers`].
    user: Vec<usize>,
    /// Per atom of the spec (its safe-set literal, either polarity).
    atoms: Vec<usize>,
}

impl GiveWay {
    /// The levels of `params.give_way` over `params`'s barriers and `spec`'s atoms; a name
    /// that is neither, or one named twice, is an error listing the names it may be.
    pub(super) fn new(params: &ShieldParams, spec: &Spec) -> Result<Self, ShieldError> {
        let last = params.give_way.len();
        let mut out = GiveWay {
            user: vec![last; params.barriers.len()],
            atoms: vec![last; spec.atoms().len()],
        };
        for (level, name) in params.give_way.iter().enumerate() {
            if params.give_way[..level].contains(name) {
                return Err(ShieldError::Config(format!(
                    "give_way: {name:?} is named twice"
                )));
            }
            let user = params.barriers.iter().position(|b| &b.name == name);
            let atom = spec.atoms().iter().position(|a| a == name);
            match (user, atom) {
                (Some(i), _) => out.user[i] = level,
                (None, Some(a)) => out.atoms[a] = level,
                (None, None) => {
                    let known: Vec<&str> = params
                        .barriers
                        .iter()
                        .map(|b| b.name.as_str())
                        .chain(spec.atoms().iter().map(String::as_str))
                        .collect();
                    return Err(ShieldError::Config(format!(
                        "give_way: {name:?} is neither a barrier nor an atom of the task; \
                         expected one of {known:?}"
                    )));
                }
            }
        }
        Ok(out)
    }

    /// The level of the rows of `source`.
    pub(super) fn level(&self, source: BarrierSource) -> usize {
        match source {
            BarrierSource::User(i) => self.user[i],
            BarrierSource::SafeSet(literal) => self.atoms[literal.atom],
        }
    }

    /// The lowest level above `after` (`None`: any) among the rows of `sources`.
    pub(super) fn next(&self, sources: &[BarrierSource], after: Option<usize>) -> Option<usize> {
        sources
            .iter()
            .map(|&s| self.level(s))
            .filter(|&l| after.is_none_or(|a| l > a))
            .min()
    }
}
