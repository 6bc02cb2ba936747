# Source this before running Loom under MPI:   . scripts/mpi_env.sh
#   mpirun -n 2 --oversubscribe build/bin/loom run scene.yaml
# (the scene's solver must be `petsc` for the solve to be distributed; see docs/plugins/solvers.md)
#
# One OpenMP and one BLAS thread per rank: N ranks x 2 threads on a 2-core machine would
# oversubscribe it, and busy-waiting threads that share a core cost far more than they save.
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}"
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
# Open MPI refuses to run as root (containers, CI) unless told twice.
if [ "$(id -u)" = "0" ]; then
  export OMPI_ALLOW_RUN_AS_ROOT=1
  export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
fi
# Allow more ranks than cores without --oversubscribe.
export OMPI_MCA_rmaps_base_oversubscribe=1
