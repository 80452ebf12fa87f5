//! Closed-loop acceptance tests live in this package's test targets
//! (`paper_scenarios.rs`, `fault_scenarios.rs`, `scenario_files.rs`); this library is
//! empty.
