/* FanLag: a tiny FMI 2.0 co-simulation FMU for tests/test_fmu_component.py.
 *
 *   electric_power = P_nom * max(c1 + f (c2 + f (c3 + f c4)), 0),  f = max(V, 0) / V_nom   [W]; 0 at f = 0 (off)
 *   lagged_power   = x,  x <- x + (1 - exp(-h / tau)) * (electric_power - x) in fmi2DoStep
 *
 * the same polynomial (Horner, clipped at 0) as service.fan.Fan and the exact discretisation of a
 * first-order lag with the input held over the step (tau <= 0: no lag). x starts in steady state
 * (x = electric_power at fmi2ExitInitializationMode); fmi2Reset restores the start values. Outputs
 * at a communication point reflect the inputs set there and the state there. Every instance keeps
 * its own state (no globals).
 *
 * Build (the test does this at test time; fmpy ships the FMI 2.0 headers in fmpy/c-code):
 *   gcc -shared -fPIC -O2 -I<fmpy>/c-code fan_lag.c -o binaries/linux64/FanLag.so -lm
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define GUID "{8c4e810f-3df3-4a00-8276-176fa3c9f003}"

enum {
    VR_FLOW = 0, VR_POWER, VR_LAGGED, VR_NOMINAL_FLOW, VR_NOMINAL_POWER,
    VR_C1, VR_C2, VR_C3, VR_C4, VR_TAU, N_VR
};

typedef struct {
    double r[N_VR];
    double lag;  /* the state x */
    double time;
    int initialized;
} Instance;

static double power(const Instance *m) {
    double flow = m->r[VR_FLOW] > 0.0 ? m->r[VR_FLOW] : 0.0;
    double f = flow / m->r[VR_NOMINAL_FLOW];
    double fraction = m->r[VR_C1] + f * (m->r[VR_C2] + f * (m->r[VR_C3] + f * m->r[VR_C4]));
    if (f <= 0.0) return 0.0;  /* the fan is off */
    return m->r[VR_NOMINAL_POWER] * (fraction > 0.0 ? fraction : 0.0);
}

/* the start values of modelDescription.xml: the state after fmi2Instantiate and fmi2Reset */
static void set_start_values(Instance *m) {
    memset(m, 0, sizeof(Instance));
    m->r[VR_NOMINAL_FLOW] = 1.5;
    m->r[VR_NOMINAL_POWER] = 1800.0;
    m->r[VR_C1] = 0.0013;
    m->r[VR_C2] = 0.147;
    m->r[VR_C3] = 0.9506;
    m->r[VR_C4] = -0.0998;
    m->r[VR_TAU] = 60.0;
}

/* inquire version and platform */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat;
    return fmi2OK;
}

/* creation and destruction */
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean logging) {
    (void)name; (void)resources; (void)functions; (void)visible; (void)logging;
    if (type != fmi2CoSimulation || guid == NULL || strcmp(guid, GUID) != 0) return NULL;
    Instance *m = malloc(sizeof(Instance));
    if (m == NULL) return NULL;
    set_start_values(m);
    return m;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

/* initialization, termination, reset */
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stopDefined, fmi2Real stop) {
    (void)tolDefined; (void)tol; (void)stopDefined; (void)stop;
    ((Instance *)c)->time = start;
    return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *m = c;
    m->lag = power(m);
    m->initialized = 1;
    return fmi2OK;
}
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { set_start_values(c); return fmi2OK; }

/* getting and setting variable values */
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= N_VR) return fmi2Error;
        if (vr[i] == VR_POWER) value[i] = power(m);
        else if (vr[i] == VR_LAGGED) value[i] = m->initialized ? m->lag : power(m);
        else value[i] = m->r[vr[i]];
    }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= N_VR || vr[i] == VR_POWER || vr[i] == VR_LAGGED) return fmi2Error;
        m->r[vr[i]] = value[i];
    }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    (void)c; (void)vr; (void)value;
    return nvr == 0 ? fmi2OK : fmi2Error;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    (void)c; (void)vr; (void)value;
    return nvr == 0 ? fmi2OK : fmi2Error;
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    (void)c; (void)vr; (void)value;
    return nvr == 0 ? fmi2OK : fmi2Error;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    (void)c; (void)vr; (void)value;
    return nvr == 0 ? fmi2OK : fmi2Error;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    (void)c; (void)vr; (void)value;
    return nvr == 0 ? fmi2OK : fmi2Error;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    (void)c; (void)vr; (void)value;
    return nvr == 0 ? fmi2OK : fmi2Error;
}

/* FMU state and directional derivatives: not supported (capability flags are false) */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)c; (void)s; (void)n;
    return fmi2Error;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)c; (void)s; (void)b; (void)n;
    return fmi2Error;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)c; (void)b; (void)n; (void)s;
    return fmi2Error;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[],
                                        fmi2Real dz[]) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    return fmi2Error;
}

/* co-simulation */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)c; (void)vr; (void)nvr; (void)order; (void)value;
    return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)c; (void)vr; (void)nvr; (void)order; (void)value;
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    (void)noSetPrior;
    Instance *m = c;
    double tau = m->r[VR_TAU];
    double share = tau > 0.0 ? -expm1(-h / tau) : 1.0;
    m->lag += share * (power(m) - m->lag);
    m->time = t + h;
    return fmi2OK;
}
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    Instance *m = c;
    if (s != fmi2LastSuccessfulTime) return fmi2Discard;
    *value = m->time;
    return fmi2OK;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}
