// The one rule for "which MPI rank is this process", read from the launcher's environment
// before (or without) MPI_Init: used by the output writer (only rank 0 writes) and by the PETSc
// solver plugin.
#pragma once

namespace loom {

/// Rank of this process in MPI_COMM_WORLD as the launcher set it: the first of
/// OMPI_COMM_WORLD_RANK (Open MPI), PMI_RANK (MPICH, Intel MPI, Hydra), PMIX_RANK (PMIx),
/// MV2_COMM_WORLD_RANK (MVAPICH2) and SLURM_PROCID (srun) that is set to a non-negative
/// integer; 0 when none is (not launched by mpirun/srun).
int launcher_rank();

/// Whether this process writes output and notes: launcher_rank() == 0.
bool is_output_rank();

}  // namespace loom
