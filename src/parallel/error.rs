//! What a run under mpirun hands back when it fails: the transport's own error, which the
//! command that started the run turns into its exit status.

/// Why a run under mpirun failed. An empty message: the ranks have said why already (each rank
/// that knew said its line before all of them stopped together).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ParallelError {
    /// The job cannot run as asked: its options, its layout of ranks, its scene or files.
    Input(String),
    /// The job failed through no fault of its input: MPI, a lost rank, an output not written.
    Failed(String),
}

pub type ParallelResult = Result<(), ParallelError>;
