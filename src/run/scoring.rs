//! Where a job's candidates are scored, shared by every kind of run: here, on workers, or on
//! an evaluator of the caller's, and what a job asks of them ([`Placement`]).

use super::abc::Config;
use crate::abc::shard::{self, Devices, Local, Workers};
use crate::error::Result;
use crate::eval::gpu::tune::ShapeWish;
use crate::eval::{Backend, Evaluator, Objective, Problem};

/// Where a run's candidates are scored.
#[derive(Default)]
pub enum Scoring<'a, 'w> {
    /// In this process, on the run's backend and devices ([`shard::here`]).
    #[default]
    Here,
    /// By the workers the function makes from the run's problem (a pool of processes or
    /// machines: [`crate::abc::shard`]); the populations are those [`Scoring::Here`] gives.
    Workers(&'a mut MakeWorkers<'w>),
    /// By the evaluator the function makes from the run's problem, in this process (the
    /// selection check scores its replicates' candidates together, [`crate::eval::records`]).
    Evaluator(&'a mut MakeEvaluator<'w>),
}

/// Makes a run's evaluator from its problem, saying what the user should know through the
/// second argument ([`crate::eval::evaluator`] of the run's backend, unless the caller scores
/// elsewhere).
pub type MakeEvaluator<'a> = dyn FnMut(Problem, &mut dyn FnMut(String)) -> Result<Box<dyn Evaluator>> + 'a;

/// Makes the workers that run a job's tasks from what it scores against and where the job
/// asks them to score (a continued run's with the continuation's backend and devices), saying
/// what the user should know through the third argument.
pub type MakeWorkers<'a> =
    dyn FnMut(Objective, &Placement, &mut dyn FnMut(String)) -> Result<Box<dyn Workers + 'a>> + 'a;

/// Where a job asks its candidates to be scored: the backend, this machine's devices and the
/// GPU scoring shape. A pool of workers takes the backend and shape to each worker.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Placement {
    pub backend: Backend,
    pub devices: Devices,
    pub shape: ShapeWish,
}

impl Placement {
    /// A run's: its backend, devices, and its recorded GPU scoring shape for dispatches of its
    /// size ([`shape_wish`]).
    pub fn of(config: &Config) -> Self {
        Self {
            backend: config.backend,
            devices: config.devices,
            shape: shape_wish(config),
        }
    }
}

impl<'w> Scoring<'_, 'w> {
    /// The same scoring for one call that takes it by value, kept for the next.
    pub fn reborrow(&mut self) -> Scoring<'_, 'w> {
        match self {
            Scoring::Here => Scoring::Here,
            Scoring::Workers(make) => Scoring::Workers(&mut **make),
            Scoring::Evaluator(make) => Scoring::Evaluator(&mut **make),
        }
    }

    /// The workers that score `objective` where `placement` says. A surface run's strings are
    /// simulated by its own evaluator, on the backend the run resolved, unless workers
    /// elsewhere take them (a caller's evaluator maker scores records).
    pub fn workers(
        &mut self,
        objective: impl Into<Objective>,
        placement: &Placement,
        note: &mut dyn FnMut(String),
    ) -> Result<Box<dyn Workers + '_>> {
        match (self, objective.into()) {
            (Scoring::Workers(make), objective) => make(objective, placement, note),
            (_, Objective::Surface(strings)) => Ok(Box::new(Local(strings))),
            (Scoring::Here, Objective::Record(problem)) => {
                shard::here(problem, placement.backend, placement.devices, placement.shape, note)
            }
            (Scoring::Evaluator(make), Objective::Record(problem)) => Ok(Box::new(Local(make(problem, note)?))),
        }
    }
}

/// What a run of `config` asks of the GPU scoring shape: its recorded one, for dispatches of
/// its size.
pub fn shape_wish(config: &Config) -> ShapeWish {
    ShapeWish {
        // The SMC sampler scores its perturbed particles as explicit candidates.
        explicit: matches!(config.sampler, crate::run::abc::SamplerConfig::Smc(_)),
        ..ShapeWish::for_run(config.gpu_shape, config.sampler.schedule().particles)
    }
}
