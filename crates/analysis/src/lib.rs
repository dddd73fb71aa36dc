//! Analysis: pure math on recorded series, no I/O.
//!
//! `series` reduces frames to interval means, `figures` computes figures of
//! merit, `model` fits the study's compensation models (`compensation`
//! holds them as data), `study` holds the definitions of the study's
//! figures, `rate` the rate-table figures, `allan` the Allan deviation and
//! its noise terms, `uncertainty` the GUM's combination and expansion of a
//! figure's uncertainty budget; `par` spreads work over two threads.

pub mod allan;
pub mod compensation;
pub mod figures;
pub mod model;
pub mod par;
pub mod rate;
pub mod series;
pub mod study;
pub mod uncertainty;
