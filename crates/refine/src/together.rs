//! Several records of one plant as one residual model: the joint fit's
//! vector holds the plant's parameters once and each record's own
//! parameters (an initial state, a sensor offset) once per record.

use std::collections::HashMap;
use std::sync::Mutex;

use twostage_models::{IoData, Prior};

use crate::refinement::ResidualModel;

/// Where each record's parameters lie in the joint fit's vector: the
/// plant's (shared) parameters first, in the model's order, then each
/// record's own parameters in turn. Without own parameters the joint
/// vector is the model's.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct JointLayout {
    q: usize,
    pub(crate) shared: Vec<usize>,
    pub(crate) own: Vec<usize>,
    records: usize,
}

impl JointLayout {
    /// The layout of `records` records of a model whose parameters marked
    /// in `per_record` belong to each record.
    pub(crate) fn new(per_record: &[bool], records: usize) -> Self {
        let (own, shared): (Vec<usize>, Vec<usize>) =
            (0..per_record.len()).partition(|&j| per_record[j]);
        Self {
            q: per_record.len(),
            shared,
            own,
            records,
        }
    }

    pub(crate) fn has_own(&self) -> bool {
        !self.own.is_empty()
    }

    /// Where record `r`'s parameters lie in the joint vector, in the
    /// model's order.
    pub(crate) fn places(&self, r: usize) -> Vec<usize> {
        let mut places = vec![0; self.q];
        for (k, &j) in self.shared.iter().enumerate() {
            places[j] = k;
        }
        let first = self.shared.len() + r * self.own.len();
        for (k, &j) in self.own.iter().enumerate() {
            places[j] = first + k;
        }
        places
    }

    /// Record `r`'s parameter vector in the joint vector `joint`.
    pub(crate) fn record_theta(&self, joint: &[f64], r: usize) -> Vec<f64> {
        self.places(r).into_iter().map(|k| joint[k]).collect()
    }

    /// The joint vector of the plant's parameters of `shared` and each
    /// record's own parameters of `own(r)` (both full parameter vectors).
    pub(crate) fn joint_vector<'a>(
        &self,
        shared: &[f64],
        own: impl Fn(usize) -> &'a [f64],
    ) -> Vec<f64> {
        let mut joint: Vec<f64> = self.shared.iter().map(|&j| shared[j]).collect();
        for r in 0..self.records {
            let theirs = own(r);
            joint.extend(self.own.iter().map(|&j| theirs[j]));
        }
        joint
    }

    /// The joint vector's prior: each record's own parameters drawn as
    /// the model's prior draws them, independently.
    pub(crate) fn prior(&self, model: &Prior) -> Result<Prior, twostage_models::SimError> {
        if !self.has_own() {
            return Ok(model.clone());
        }
        let marginals = model.marginals();
        let mut joint: Vec<_> = self.shared.iter().map(|&j| marginals[j]).collect();
        for _ in 0..self.records {
            joint.extend(self.own.iter().map(|&j| marginals[j]));
        }
        Ok(Prior::new(joint)?.with_sampling(model.sampling()))
    }
}

/// Several records as one: the residuals of each record in turn, each at
/// its parameters in the joint vector. The record a search hands it
/// stands for them all.
pub(crate) struct Together<'a, M> {
    pub(crate) model: &'a M,
    pub(crate) records: Vec<&'a IoData>,
    pub(crate) layout: JointLayout,
    prior: Prior,
    /// With own parameters, the residuals of the last two batches by
    /// record and parameter bits: a change of one record's own parameter
    /// leaves the others' residuals as they were, and a Jacobian's
    /// forward differences find its point's in the batch before.
    memo: Mutex<Memo>,
}

#[derive(Default)]
struct Memo {
    current: HashMap<(usize, Vec<u64>), Vec<f64>>,
    previous: HashMap<(usize, Vec<u64>), Vec<f64>>,
}

impl Memo {
    fn get(&self, key: &(usize, Vec<u64>)) -> Option<&Vec<f64>> {
        self.current.get(key).or_else(|| self.previous.get(key))
    }

    fn next_batch(&mut self) {
        self.previous = std::mem::take(&mut self.current);
    }
}

impl<'a, M: ResidualModel> Together<'a, M> {
    pub(crate) fn new(
        model: &'a M,
        records: Vec<&'a IoData>,
        per_record: &[bool],
    ) -> Result<Self, M::Error> {
        let layout = JointLayout::new(per_record, records.len());
        let prior =
            layout
                .prior(model.prior())
                .map_err(|source| crate::RefineError::Simulation {
                    what: "the joint fit's prior",
                    source,
                })?;
        Ok(Self {
            model,
            records,
            layout,
            prior,
            memo: Mutex::new(Memo::default()),
        })
    }

    /// Each record's parameters at the joint vector `joint`, with the
    /// record's place.
    fn pairs(&self, joint: &[f64]) -> impl Iterator<Item = (usize, Vec<f64>)> + '_ {
        let joint = joint.to_vec();
        (0..self.records.len()).map(move |r| (r, self.layout.record_theta(&joint, r)))
    }
}

fn key(r: usize, theta: &[f64]) -> (usize, Vec<u64>) {
    (r, theta.iter().map(|v| v.to_bits()).collect())
}

impl<M: ResidualModel> ResidualModel for Together<'_, M> {
    type Error = M::Error;

    fn prior(&self) -> &Prior {
        &self.prior
    }

    fn residuals(&self, joint: &[f64], _: &IoData, residuals: &mut [f64]) -> Result<(), M::Error> {
        let mut rest = residuals;
        for (r, theta) in self.pairs(joint) {
            let record = self.records[r];
            let (mine, after) = rest.split_at_mut(self.model.n_residuals(record));
            self.model.residuals(&theta, record, mine)?;
            rest = after;
        }
        Ok(())
    }

    fn n_residuals(&self, _: &IoData) -> usize {
        self.records.iter().map(|r| self.model.n_residuals(r)).sum()
    }

    fn residual_runs(&self, _: &IoData) -> Vec<usize> {
        self.records
            .iter()
            .flat_map(|r| self.model.residual_runs(r))
            .collect()
    }

    /// Every point on every record in one batch of the model's, so that a
    /// simulator gets each record's points together; with own parameters,
    /// a record's residuals at parameters already evaluated (in this
    /// batch or the one before) are not asked for again.
    fn residuals_batch(
        &self,
        pairs: &[(&[f64], &IoData)],
        residuals: &mut [Vec<f64>],
    ) -> Vec<Result<(), M::Error>> {
        let each: Vec<(usize, Vec<f64>)> = pairs
            .iter()
            .flat_map(|(joint, _)| self.pairs(joint))
            .collect();
        let mut memo = self
            .memo
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        memo.next_batch();
        // Which evaluation answers each record's place: its own, or an
        // earlier one of the same record at the same parameters.
        let mut asked: Vec<usize> = Vec::with_capacity(each.len());
        let mut first_of: HashMap<(usize, Vec<u64>), usize> = HashMap::new();
        let mut answered_by: Vec<Option<usize>> = Vec::with_capacity(each.len());
        for (k, (r, theta)) in each.iter().enumerate() {
            if !self.layout.has_own() {
                asked.push(k);
                answered_by.push(None);
                continue;
            }
            let key = key(*r, theta);
            if memo.get(&key).is_some() {
                answered_by.push(None);
            } else if let Some(&earlier) = first_of.get(&key) {
                answered_by.push(Some(earlier));
            } else {
                first_of.insert(key, k);
                asked.push(k);
                answered_by.push(None);
            }
        }
        let batch: Vec<(&[f64], &IoData)> = asked
            .iter()
            .map(|&k| (each[k].1.as_slice(), self.records[each[k].0]))
            .collect();
        let mut parts = vec![Vec::new(); batch.len()];
        let answers = self.model.residuals_batch(&batch, &mut parts);
        let mut results: Vec<Option<Result<Vec<f64>, M::Error>>> =
            (0..each.len()).map(|_| None).collect();
        for ((&k, answer), part) in asked.iter().zip(answers).zip(parts) {
            results[k] = Some(answer.map(|()| part));
        }
        if self.layout.has_own() {
            for (k, (r, theta)) in each.iter().enumerate() {
                if let Some(Ok(part)) = &results[k] {
                    memo.current.insert(key(*r, theta), part.clone());
                }
            }
        }
        let per_point = self.records.len();
        residuals
            .iter_mut()
            .enumerate()
            .map(|(p, out)| {
                out.clear();
                let mut failed = None;
                for k in p * per_point..(p + 1) * per_point {
                    let (r, theta) = &each[k];
                    let found = match &results[k] {
                        Some(Ok(part)) => Ok(part.as_slice()),
                        Some(Err(_)) => Err(()),
                        None => match answered_by[k].and_then(|e| results[e].as_ref()) {
                            Some(Ok(part)) => Ok(part.as_slice()),
                            Some(Err(_)) => Err(()),
                            None => memo.get(&key(*r, theta)).map(Vec::as_slice).ok_or(()),
                        },
                    };
                    match found {
                        Ok(part) => out.extend_from_slice(part),
                        Err(()) => {
                            failed = failed.or_else(|| Some(self.failure(k, &each, &mut results)))
                        }
                    }
                }
                failed.map_or(Ok(()), Err)
            })
            .collect()
    }

    fn trials_at_once(&self) -> usize {
        self.model.trials_at_once()
    }
}

impl<M: ResidualModel> Together<'_, M> {
    /// The error of the evaluation at `each[k]`: its own where it was
    /// asked for, else the record evaluated again alone for one (an error
    /// is not copied from the evaluation that answered it).
    fn failure(
        &self,
        k: usize,
        each: &[(usize, Vec<f64>)],
        results: &mut [Option<Result<Vec<f64>, M::Error>>],
    ) -> M::Error {
        if let Some(Err(e)) = results[k].take() {
            return e;
        }
        let (r, theta) = &each[k];
        let record = self.records[*r];
        let mut scratch = vec![0.0; self.model.n_residuals(record)];
        match self.model.residuals(theta, record, &mut scratch) {
            Err(e) => e,
            Ok(()) => crate::RefineError::Numerical {
                what: "a record's residuals failed in a batch and not alone".into(),
            }
            .into(),
        }
    }
}
