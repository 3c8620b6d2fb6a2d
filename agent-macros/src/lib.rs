//! Procedural macros for embodied-agents. Use them through the `embodied` crate,
//! which re-exports them next to the traits they implement (as `serde` does with
//! `serde_derive`); the generated code names `::embodied`.
//!
//! * Derives that describe buffers and memory, so that the runtime and the spec tools
//!   know every field's name, type and freshness: [`Group`](derive@Group),
//!   [`Buffers`](derive@Buffers), [`Memory`](derive@Memory),
//!   [`Subsystem`](derive@Subsystem).
//! * [`fsm!`]: behaviours and their FSM in the paper's notation, checked at compile
//!   time by the spec checker.
//! * [`agent!`]: the types and one trait per subsystem generated from a RON spec,
//!   checked at compile time.
//!
//! The crate only parses, checks and generates; every semantic lives in
//! `agent-core`, every rule in `agent-spec`. Each macro is a pipeline of stages
//! (parse, check, generate) written over `proc_macro2` so that each stage is unit
//! tested on token input.

mod agent;
mod chain;
mod derive;
mod fsm;
mod synth;
mod tally;
mod util;

use proc_macro::TokenStream;

/// Describe a group of buffers connected to one peer, and implement `Group`.
///
/// Every field is an `In<T>` or every field an `Out<T>`; the attribute names the kind
/// of component at the other end (`Control`, `VirtualEffector`, `VirtualReceptor`,
/// `RealEffector`, `RealReceptor`):
///
/// ```
/// use embodied::prelude::*;
///
/// #[derive(Debug, Default, Group)]
/// #[group(peer = VirtualEffector)]
/// struct ToValve {
///     flow: Out<f64>,
/// }
///
/// assert_eq!(<ToValve as Group>::PEER, NodeKind::VirtualEffector);
/// ```
///
/// Implements `Group` (the peer kind), `Fields` (each buffer's name and payload type)
/// and `Buffers` (the group's shape and the freshness of its buffers). A group
/// without buffers is described as an input group.
#[proc_macro_derive(Group, attributes(group))]
pub fn derive_group(input: TokenStream) -> TokenStream {
    let input = syn::parse_macro_input!(input as syn::DeriveInput);
    derive::parse_group(input)
        .map(|m| derive::generate_group(&m))
        .unwrap_or_else(syn::Error::into_compile_error)
        .into()
}

/// Describe an input or output struct: a subsystem's struct of `#[derive(Group)]`
/// groups, or a driver's struct of `In<T>` (or `Out<T>`) buffers.
///
/// Implements `Buffers`: the groups with their field names, peers, buffers and
/// types, and `fresh()`, the freshness of every buffer as one bit set.
#[proc_macro_derive(Buffers)]
pub fn derive_buffers(input: TokenStream) -> TokenStream {
    let input = syn::parse_macro_input!(input as syn::DeriveInput);
    derive::parse_buffers(input)
        .map(|m| derive::generate_buffers(&m))
        .unwrap_or_else(syn::Error::into_compile_error)
        .into()
}

/// Describe a memory struct: implements `Fields` with each field's name and type.
#[proc_macro_derive(Memory)]
pub fn derive_memory(input: TokenStream) -> TokenStream {
    let input = syn::parse_macro_input!(input as syn::DeriveInput);
    derive::parse_memory(input)
        .map(|m| derive::generate_memory(&m))
        .unwrap_or_else(syn::Error::into_compile_error)
        .into()
}

/// Implement `Subsystem` on a marker type, with its shape:
///
/// ```
/// use embodied::prelude::*;
///
/// #[derive(Debug, Default, Group)]
/// #[group(peer = RealEffector)]
/// struct ToPump {
///     flow: Out<f64>,
/// }
///
/// #[derive(Debug, Default, Buffers)]
/// struct StationOutput {
///     pump: ToPump,
/// }
///
/// #[derive(Clone, Debug, Default, Memory)]
/// struct StationMemory {
///     order: Option<f64>,
/// }
///
/// #[derive(Subsystem)]
/// #[subsystem(kind = Control, memory = StationMemory, input = (), output = StationOutput)]
/// struct Station;
///
/// assert_eq!(Station::KIND, SubsystemKind::Control);
/// ```
///
/// The memory must derive `Memory` and the input and output structs `Buffers`.
#[proc_macro_derive(Subsystem, attributes(subsystem))]
pub fn derive_subsystem(input: TokenStream) -> TokenStream {
    let input = syn::parse_macro_input!(input as syn::DeriveInput);
    derive::parse_subsystem(input)
        .map(|m| derive::generate_subsystem(&m))
        .unwrap_or_else(syn::Error::into_compile_error)
        .into()
}

/// Counts that add up: implements `embodied::app::Tally` (the application
/// layer's, feature `app`) for a struct by tallying each field with the
/// other's, so every field's type must be `Tally` itself (numbers saturate,
/// lists join, tuples and derived structs go field by field). What a
/// deployment's processes report at their end is added up this way.
///
/// ```
/// use embodied::app::Tally;
///
/// #[derive(Debug, Default, PartialEq, Tally)]
/// struct Health {
///     rejected: u64,
///     stops: Vec<String>,
/// }
///
/// #[derive(Debug, Default, PartialEq, Tally)]
/// struct Counts {
///     solves: u32,
///     health: Health,
///     delivered_lost: (u64, u64),
/// }
///
/// let mut run = Counts { solves: 3, delivered_lost: (10, 1), ..Counts::default() };
/// run.tally(Counts {
///     solves: u32::MAX,
///     health: Health { rejected: 2, stops: vec!["at 1 s".into()] },
///     delivered_lost: (5, 0),
/// });
/// assert_eq!(run.solves, u32::MAX);
/// assert_eq!(run.health, Health { rejected: 2, stops: vec!["at 1 s".into()] });
/// assert_eq!(run.delivered_lost, (15, 1));
/// ```
#[proc_macro_derive(Tally)]
pub fn derive_tally(input: TokenStream) -> TokenStream {
    let input = syn::parse_macro_input!(input as syn::DeriveInput);
    tally::derive_tally(input)
        .unwrap_or_else(syn::Error::into_compile_error)
        .into()
}

/// Behaviours and the FSM of one subsystem, in the paper's notation. Evaluates to
/// `Result<Fsm<S>, FsmBuildError>`: exactly the `FsmBuilder` chain one would write
/// by hand, so the FSM runs with no cost added by the macro.
///
/// ```
/// # use embodied::prelude::*;
/// # #[derive(Debug, Default, Group)]
/// # #[group(peer = RealEffector)]
/// # struct ToPump { flow: Out<f64> }
/// # #[derive(Debug, Default, Buffers)]
/// # struct StationOutput { pump: ToPump }
/// # #[derive(Clone, Debug, Default, Memory)]
/// # struct StationMemory { order: Option<f64>, filled: f64 }
/// # #[derive(Subsystem)]
/// # #[subsystem(kind = Control, memory = StationMemory, input = (), output = StationOutput)]
/// # struct Station;
/// // Transition functions (memory, inputs -> a part of the outputs or the memory)
/// // and predicates (memory, inputs -> bool).
/// fn stop_pump(_: &StationMemory, _: &(), y: &mut ToPump) {
///     y.flow.set(0.0);
/// }
/// fn take_order(m: &mut StationMemory, _: &()) {
///     m.order.get_or_insert(2.0);
/// }
/// fn fill_flow(m: &StationMemory, _: &(), y: &mut ToPump) {
///     y.flow.set(m.order.unwrap_or(0.0) - m.filled);
/// }
/// fn order_valid(m: &StationMemory, _: &()) -> bool {
///     m.order.is_some_and(|o| o > 0.0)
/// }
/// fn reached(m: &StationMemory, _: &()) -> bool {
///     m.filled >= m.order.unwrap_or(0.0)
/// }
///
/// # fn main() -> Result<(), embodied::FsmBuildError> {
/// let fsm = fsm! {
///     subsystem Station;
///     predicates {
///         has_order: |m: &StationMemory, _| m.order.is_some(),
///         order_valid,                       // a function `order_valid` in scope
///         reached,
///     }
///     // B(f, f^τ): kind, name, terminal condition, the parts of f by target.
///     while idle until has_order { pump <- stop_pump, memory <- take_order }
///     repeat fill until reached { pump <- fill_flow }
///     repeat refuse until true { pump <- stop_pump }
///     initial idle;
///     idle -> fill when order_valid;       // arcs with initial conditions
///     idle -> refuse when !order_valid;
///     refuse -> idle;                      // `when true`
///     final fill;                          // the FSM ends when `fill` ends
/// }?;
/// assert_eq!(fsm.behaviour(1).map(|b| b.name()), Some("fill"));
/// # Ok(())
/// # }
/// ```
///
/// A part `target <- function` writes `memory`, `common`, or the output group in
/// field `target` (a field named `memory` or `common` is written `r#memory <- f`);
/// the function is a path or a closure, named in specs after its path (a closure
/// after its behaviour and target: `fill_memory`). At compile time the FSM goes
/// through the spec checker: unknown or duplicate names, unreachable behaviours,
/// behaviours without a way out, finals with arcs, conditions that do not parse, and
/// arcs that may overlap or leave a gap (with the predicate values that show it) are
/// compile errors on the tokens concerned. `relations { exclusive(a, b), a => b }`
/// states what the arc proof may assume.
#[proc_macro]
pub fn fsm(input: TokenStream) -> TokenStream {
    fsm::expand(input.into()).into()
}

/// Types and traits generated from a RON spec, checked at compile time.
///
/// ```
/// use embodied::prelude::*;
///
/// // A spec of this repository's tests, from the folder of agent-macros' Cargo.toml.
/// embodied::agent!(spec = "../tests/specs/valid/minimal.ron", agent = "a1");
///
/// assert_eq!(c1::C1::KIND, SubsystemKind::Control);
/// let memory = c1::Memory { count: 3 };
/// assert_eq!(memory.count, 3);
/// ```
///
/// The path is relative to the crate's `Cargo.toml` (`CARGO_MANIFEST_DIR`), or else
/// to the directory of the file that invokes the macro. A spec
/// the checker rejects is a compile error per finding, `file:line:col: error[code]:
/// message`. For each subsystem `c1` of the agent, a module `c1` holds the marker
/// type `C1`, `Memory`, the groups (`FromE1`, `ToE1`...), `Input`, `Output`, a trait
/// `Functions` with one method per transition function and predicate of the spec,
/// and `fsm::<T: Functions>()` building the spec's FSM over the implementation. For
/// each device `E1`, a module `E1` holds its `Input` and `Output` buffers.
#[proc_macro]
pub fn agent(input: TokenStream) -> TokenStream {
    let invoker = proc_macro::Span::call_site().local_file();
    agent::expand(input.into(), invoker).into()
}
