/* The one instance and stepping core of a native lsc FMU, under the FMI 2.0 and the FMI 3.0
 * API layers (fmi2Functions.c, fmi3Functions.c: each checks its API's call sequence and
 * arguments, then calls one function here), as the Modelica Reference-FMUs lay theirs out:
 *   lsc_fmu.h            the instance and its state, the backend contract, logging, checks;
 *   inputs.c             the inputs' values received and their estimated derivatives;
 *   model_constant.c     the model backend of constant coefficients (exact steps), or
 *   model_timevarying.c  the one of time-varying coefficients (Chebyshev tables, Magnus steps);
 *   instance.c           making an instance, the experiment, initialization, get and set;
 *   cosimulation.c       the communication step, discards, input and output derivatives;
 *   model_exchange.c     the states and their derivatives for the host's integrator;
 *   fmu_state.c          FMU states and their serialization;
 *   directional.c        partial derivatives: directional and adjoint products;
 *   lsc_linalg.h         products, LU, the matrix exponential.
 * Everything that belongs to one model (sizes, value references, the matrices or tables,
 * the C of the forcing and the custom outputs) is in the generated "model.h"; the build
 * chooses the backend by what it writes there (LSC_TIME_VARYING), here and nowhere else.
 * The files form one translation unit with the layer that includes this one: every
 * function but the layer's API functions is static, so no other symbol leaves the library.
 * One struct per instance, allocated at instantiation: no global mutable state, no
 * allocation per step. The core knows neither FMI version: messages start with the name
 * of the API function the layer passes in. */
#include "lsc_fmu.h"
#include "inputs.c"
#ifdef LSC_TIME_VARYING
#include "model_timevarying.c"
#else
#include "model_constant.c"
#endif
#include "instance.c"
#include "cosimulation.c"
#include "model_exchange.c"
#include "fmu_state.c"
#include "directional.c"
