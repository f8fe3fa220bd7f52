//! A model file's parameters and their priors, checked by line and key.

use toml::Spanned;
use twostage_models::{Marginal, ModelSpec};

use super::locator::Locator;
use super::raw::*;
use crate::error::Result;

impl Locator<'_> {
    pub(super) fn parameters(
        &self,
        raw: &[Spanned<RawParameter>],
        base: Option<&ModelSpec>,
    ) -> Result<(Vec<String>, Vec<Marginal>)> {
        if let Some(base) = base {
            if raw.is_empty() {
                return Ok((
                    base.param_names().to_vec(),
                    base.prior().marginals().to_vec(),
                ));
            }
            if raw.len() != base.n_params() {
                return Err(self.error(
                    Some(raw[0].span()),
                    "parameter",
                    format!(
                        "the built-in source has {} parameter(s) ({}); give one [[parameter]] \
                         each, in that order, or none to keep its priors",
                        base.n_params(),
                        base.param_names().join(", ")
                    ),
                ));
            }
        } else if raw.is_empty() {
            return Err(self.error(
                None,
                "parameter",
                "no [[parameter]]: give each parameter a name and a prior".into(),
            ));
        }
        let mut names = Vec::with_capacity(raw.len());
        let mut seen = std::collections::HashSet::with_capacity(raw.len());
        let mut marginals = Vec::with_capacity(raw.len());
        for (j, p) in raw.iter().enumerate() {
            let p_ref = p.get_ref();
            let name = p_ref.name.get_ref().trim().to_string();
            if name.is_empty() || !seen.insert(name.clone()) {
                return Err(self.error(
                    Some(p_ref.name.span()),
                    "parameter.name",
                    format!("'{name}' is empty or used twice: every parameter needs its own name"),
                ));
            }
            let marginal = match (&p_ref.prior, base) {
                (Some(prior), _) => self.marginal(prior, &name, j)?,
                (None, Some(base)) => base.prior().marginals()[j],
                (None, None) => {
                    return Err(self.error(
                        Some(p.span()),
                        "parameter.prior",
                        format!(
                            "parameter '{name}' has no prior: add prior = {{ dist = \"uniform\", \
                             low = ..., high = ... }} (or normal, lognormal, truncnormal)"
                        ),
                    ));
                }
            };
            names.push(name);
            marginals.push(marginal);
        }
        Ok((names, marginals))
    }

    pub(super) fn marginal(
        &self,
        prior: &Spanned<RawPrior>,
        name: &str,
        index: usize,
    ) -> Result<Marginal> {
        let raw = prior.get_ref();
        let dist = raw.dist.get_ref().as_str();
        let key = "parameter.prior";
        let needs: &[&str] = match dist {
            "uniform" => &["low", "high"],
            "normal" | "lognormal" => &["mu", "sigma"],
            "truncnormal" => &["mu", "sigma", "low", "high"],
            other => {
                return Err(self.error(
                    Some(raw.dist.span()),
                    "parameter.prior.dist",
                    format!(
                        "parameter '{name}': unknown distribution '{other}': use uniform, \
                         normal, lognormal or truncnormal"
                    ),
                ));
            }
        };
        let given = [
            ("low", raw.low),
            ("high", raw.high),
            ("mu", raw.mu),
            ("sigma", raw.sigma),
        ];
        for (k, v) in given {
            if v.is_some() != needs.contains(&k) {
                return Err(self.error(
                    Some(prior.span()),
                    &format!("{key}.{k}"),
                    format!(
                        "parameter '{name}': a {dist} prior takes exactly {}",
                        needs.join(", ")
                    ),
                ));
            }
        }
        let v = |x: Option<f64>| x.unwrap_or(f64::NAN);
        let marginal = match dist {
            "uniform" => Marginal::Uniform {
                low: v(raw.low),
                high: v(raw.high),
            },
            "normal" => Marginal::Normal {
                mu: v(raw.mu),
                sigma: v(raw.sigma),
            },
            "lognormal" => Marginal::LogNormal {
                mu: v(raw.mu),
                sigma: v(raw.sigma),
            },
            _ => Marginal::TruncatedNormal {
                mu: v(raw.mu),
                sigma: v(raw.sigma),
                low: v(raw.low),
                high: v(raw.high),
            },
        };
        marginal
            .check(index)
            .map_err(|e| self.error(Some(prior.span()), key, format!("parameter '{name}': {e}")))?;
        Ok(marginal)
    }
}
