/* The FMI 3.0 C interface the Co-Simulation FMU implements, declared from
 * the type definitions and function signatures of the FMI 3.0 standard
 * (chapter 2.2, common functions, and chapter 4, Co-Simulation). Only this
 * project's FMU and its tests include it; every function it declares is
 * exported from the FMI 3.0 binary with default visibility, everything else
 * stays hidden. The Model Exchange and Scheduled Execution functions beyond
 * their instantiation are not declared: the FMU provides neither interface. */
#ifndef TWIN_FMU_FMI3_API_H
#define TWIN_FMU_FMI3_API_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define TWIN_FMI3_EXPORT __attribute__((visibility("default")))

typedef void* fmi3Instance;
typedef void* fmi3InstanceEnvironment;
typedef void* fmi3FMUState;
typedef uint32_t fmi3ValueReference;
typedef float fmi3Float32;
typedef double fmi3Float64;
typedef int8_t fmi3Int8;
typedef uint8_t fmi3UInt8;
typedef int16_t fmi3Int16;
typedef uint16_t fmi3UInt16;
typedef int32_t fmi3Int32;
typedef uint32_t fmi3UInt32;
typedef int64_t fmi3Int64;
typedef uint64_t fmi3UInt64;
typedef bool fmi3Boolean;
typedef char fmi3Char;
typedef const fmi3Char* fmi3String;
typedef uint8_t fmi3Byte;
typedef const fmi3Byte* fmi3Binary;
typedef bool fmi3Clock;

#define fmi3True true
#define fmi3False false

typedef enum { fmi3OK, fmi3Warning, fmi3Discard, fmi3Error, fmi3Fatal } fmi3Status;
typedef enum { fmi3Independent, fmi3Constant, fmi3Fixed, fmi3Tunable, fmi3Discrete, fmi3Dependent } fmi3DependencyKind;
typedef enum { fmi3IntervalNotYetKnown, fmi3IntervalUnchanged, fmi3IntervalChanged } fmi3IntervalQualifier;

typedef void (*fmi3LogMessageCallback)(fmi3InstanceEnvironment instanceEnvironment, fmi3Status status,
                                       fmi3String category, fmi3String message);
typedef void (*fmi3IntermediateUpdateCallback)(fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3Float64 intermediateUpdateTime,
                                               fmi3Boolean intermediateVariableSetRequested,
                                               fmi3Boolean intermediateVariableGetAllowed,
                                               fmi3Boolean intermediateStepFinished, fmi3Boolean canReturnEarly,
                                               fmi3Boolean* earlyReturnRequested, fmi3Float64* earlyReturnTime);
typedef void (*fmi3ClockUpdateCallback)(fmi3InstanceEnvironment instanceEnvironment);
typedef void (*fmi3LockPreemptionCallback)(void);
typedef void (*fmi3UnlockPreemptionCallback)(void);

/* Version, logging, creation and destruction of instances. */
TWIN_FMI3_EXPORT const char* fmi3GetVersion(void);
TWIN_FMI3_EXPORT fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                                                const fmi3String categories[]);
TWIN_FMI3_EXPORT fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                                           fmi3String resourcePath, fmi3Boolean visible,
                                                           fmi3Boolean loggingOn,
                                                           fmi3InstanceEnvironment instanceEnvironment,
                                                           fmi3LogMessageCallback logMessage);
TWIN_FMI3_EXPORT fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath, fmi3Boolean visible,
    fmi3Boolean loggingOn, fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
    const fmi3ValueReference requiredIntermediateVariables[], size_t nRequiredIntermediateVariables,
    fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
    fmi3IntermediateUpdateCallback intermediateUpdate);
TWIN_FMI3_EXPORT fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath, fmi3Boolean visible,
    fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
    fmi3ClockUpdateCallback clockUpdate, fmi3LockPreemptionCallback lockPreemption,
    fmi3UnlockPreemptionCallback unlockPreemption);
TWIN_FMI3_EXPORT void fmi3FreeInstance(fmi3Instance instance);

/* Initialization, events, termination. */
TWIN_FMI3_EXPORT fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                                        fmi3Float64 tolerance, fmi3Float64 startTime,
                                                        fmi3Boolean stopTimeDefined, fmi3Float64 stopTime);
TWIN_FMI3_EXPORT fmi3Status fmi3ExitInitializationMode(fmi3Instance instance);
TWIN_FMI3_EXPORT fmi3Status fmi3EnterEventMode(fmi3Instance instance);
TWIN_FMI3_EXPORT fmi3Status fmi3Terminate(fmi3Instance instance);
TWIN_FMI3_EXPORT fmi3Status fmi3Reset(fmi3Instance instance);

/* Getting and setting variable values, one function per type. */
#define TWIN_FMI3_GET_SET(T)                                                                                       \
  TWIN_FMI3_EXPORT fmi3Status fmi3Get##T(fmi3Instance instance, const fmi3ValueReference valueReferences[],       \
                                         size_t nValueReferences, fmi3##T values[], size_t nValues);              \
  TWIN_FMI3_EXPORT fmi3Status fmi3Set##T(fmi3Instance instance, const fmi3ValueReference valueReferences[],       \
                                         size_t nValueReferences, const fmi3##T values[], size_t nValues);
TWIN_FMI3_GET_SET(Float32)
TWIN_FMI3_GET_SET(Float64)
TWIN_FMI3_GET_SET(Int8)
TWIN_FMI3_GET_SET(UInt8)
TWIN_FMI3_GET_SET(Int16)
TWIN_FMI3_GET_SET(UInt16)
TWIN_FMI3_GET_SET(Int32)
TWIN_FMI3_GET_SET(UInt32)
TWIN_FMI3_GET_SET(Int64)
TWIN_FMI3_GET_SET(UInt64)
TWIN_FMI3_GET_SET(Boolean)
TWIN_FMI3_GET_SET(String)
#undef TWIN_FMI3_GET_SET
TWIN_FMI3_EXPORT fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                          size_t nValueReferences, size_t valueSizes[], fmi3Binary values[],
                                          size_t nValues);
TWIN_FMI3_EXPORT fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                          size_t nValueReferences, const size_t valueSizes[],
                                          const fmi3Binary values[], size_t nValues);
TWIN_FMI3_EXPORT fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                         size_t nValueReferences, fmi3Clock values[]);
TWIN_FMI3_EXPORT fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                         size_t nValueReferences, const fmi3Clock values[]);

/* Variable dependencies. */
TWIN_FMI3_EXPORT fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                                                fmi3ValueReference valueReference,
                                                                size_t* nDependencies);
TWIN_FMI3_EXPORT fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                                        size_t elementIndicesOfDependent[],
                                                        fmi3ValueReference independents[],
                                                        size_t elementIndicesOfIndependents[],
                                                        fmi3DependencyKind dependencyKinds[], size_t nDependencies);

/* FMU state. */
TWIN_FMI3_EXPORT fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState* FMUState);
TWIN_FMI3_EXPORT fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState);
TWIN_FMI3_EXPORT fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState* FMUState);
TWIN_FMI3_EXPORT fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t* size);
TWIN_FMI3_EXPORT fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                                  fmi3Byte serializedState[], size_t size);
TWIN_FMI3_EXPORT fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                                    size_t size, fmi3FMUState* FMUState);

/* Partial derivatives. */
TWIN_FMI3_EXPORT fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                                         size_t nUnknowns, const fmi3ValueReference knowns[],
                                                         size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                                         fmi3Float64 sensitivity[], size_t nSensitivity);
TWIN_FMI3_EXPORT fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                                     size_t nUnknowns, const fmi3ValueReference knowns[],
                                                     size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                                     fmi3Float64 sensitivity[], size_t nSensitivity);

/* Configuration mode, clocks, discrete states. */
TWIN_FMI3_EXPORT fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance);
TWIN_FMI3_EXPORT fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance);
TWIN_FMI3_EXPORT fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                                   size_t nValueReferences, fmi3Float64 intervals[],
                                                   fmi3IntervalQualifier qualifiers[]);
TWIN_FMI3_EXPORT fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                                    size_t nValueReferences, fmi3UInt64 counters[],
                                                    fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]);
TWIN_FMI3_EXPORT fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                                size_t nValueReferences, fmi3Float64 shifts[]);
TWIN_FMI3_EXPORT fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                                 size_t nValueReferences, fmi3UInt64 counters[],
                                                 fmi3UInt64 resolutions[]);
TWIN_FMI3_EXPORT fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                                   size_t nValueReferences, const fmi3Float64 intervals[]);
TWIN_FMI3_EXPORT fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                                    size_t nValueReferences, const fmi3UInt64 counters[],
                                                    const fmi3UInt64 resolutions[]);
TWIN_FMI3_EXPORT fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                                size_t nValueReferences, const fmi3Float64 shifts[]);
TWIN_FMI3_EXPORT fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                                 size_t nValueReferences, const fmi3UInt64 counters[],
                                                 const fmi3UInt64 resolutions[]);
TWIN_FMI3_EXPORT fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance);
TWIN_FMI3_EXPORT fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean* discreteStatesNeedUpdate,
                                                     fmi3Boolean* terminateSimulation,
                                                     fmi3Boolean* nominalsOfContinuousStatesChanged,
                                                     fmi3Boolean* valuesOfContinuousStatesChanged,
                                                     fmi3Boolean* nextEventTimeDefined, fmi3Float64* nextEventTime);

/* Co-Simulation. */
TWIN_FMI3_EXPORT fmi3Status fmi3EnterStepMode(fmi3Instance instance);
TWIN_FMI3_EXPORT fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                                     size_t nValueReferences, const fmi3Int32 orders[],
                                                     fmi3Float64 values[], size_t nValues);
TWIN_FMI3_EXPORT fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                                       fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean* eventHandlingNeeded, fmi3Boolean* terminateSimulation,
                                       fmi3Boolean* earlyReturn, fmi3Float64* lastSuccessfulTime);

#ifdef __cplusplus
}
#endif

#endif
