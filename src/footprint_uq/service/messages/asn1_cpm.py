"""The ASN.1 modules of the CPM subset footprint-uq sends (ETSI TS 103 324 Release 2 + TS 102 894-2 CDD).

Written for this project from the published definitions (TS 103 324 V2.1.1 ``CPM-PDU-Descriptions``,
``CPM-OriginatingStationContainers``, ``CPM-PerceivedObjectContainer``; the CDD
``ETSI-ITS-CDD``), one module per CDD release (:data:`CDD_RELEASES`, :data:`CPM_ASN1_BY_CDD`):

* ``"2.1.1"``: TS 103 324 V2.1.1 with ETSI-ITS-CDD V2.1.1 (major-version 3, minor-version 1);
* ``"2.2.1"``: the same CPM with ETSI-ITS-CDD V2.2.1 (major-version 4); CDD V2.4.1 is the same on the wire
  for everything this subset sends.  What reaches the wire differs in two places:
  ``LowerTriangularPositiveSemidefiniteMatrixColumns`` gains an extension marker (one more bit per matrix)
  and the VRU sub-profiles (``VruSubProfilePedestrian``, ``...Bicyclist``, ``...Motorcyclist``,
  ``...Animal``) change from ENUMERATED (root index, 3 or 4 bits) to ``INTEGER (0..15)`` (4 bits).
  A receiver decodes only the release it compiled: a 2.1.1 payload with a correlation matrix or a VRU
  class does not decode (or decodes wrong) with the 2.2.1 modules and vice versa.  Only what footprint-uq emits is
defined with its real type; everything else keeps its *place* so that the unaligned PER
bits of what we send are those of the full standard:

* an OPTIONAL component we never send is declared with the placeholder type ``NotSent``
  (``NULL``): its presence bit is in the preamble exactly as in the standard (one bit per
  OPTIONAL/DEFAULT component), and an absent component contributes no other bits;
* a CHOICE alternative we never choose is declared ``NotSent`` too: the index of a
  CHOICE depends only on the number and order of its root alternatives;
* ``WrappedCpmContainer.containerData`` is an open type in the standard (an information
  object set keyed by ``containerId``); X.691 clause 11.2 encodes an open type as the
  complete encoding of the actual type, padded to octets, preceded by an unconstrained
  length in octets -- bit for bit an unconstrained ``OCTET STRING``.  The subset declares
  it ``OCTET STRING`` and :mod:`footprint_uq.service.messages.cpm` puts the UPER encoding
  of the container in it (``OriginatingRsuContainer`` for ``containerId`` 2,
  ``SensorInformationContainer`` for 3, ``PerceptionRegionContainer`` for 4,
  ``PerceivedObjectContainer`` for 5: the ids of ``CPM-PDU-Descriptions``);
* ``PolygonalShape.polygon`` is ``SequenceOfCartesianPosition3d (SIZE(3..16,...))`` in the CDD: a SIZE
  constraint applied serially to a type that has its own ``SIZE(1..16,...)``.  X.680 (serial application of
  constraints) makes the effective constraint of the result the last one, ``SIZE(3..16,...)``: PER writes the
  count as ``n - 3`` in 4 bits after the extension bit (as asn1c does: its PER constraint for ``polygon`` in
  etsi_its_messages' generated ``cpm_ts_PolygonalShape.c`` is ``SIZE(3..16,...)``).  The subset writes that
  effective constraint.
  asn1tools 0.169 ignores the serial constraint (it writes ``n - 1``) and pycrate cannot parse it; the tests
  give both the effective constraint, in memory (``tests/test_cpm_official.py``);
* a ``Shape`` is always ``polygonal`` here (the other alternatives are ``NotSent``), without
  ``height``; ``SensorType`` is written as its range ``(0..31)`` (``monovideo`` = 3, the named numbers
  are not PER-visible);
* the constraint ``TrafficParticipantType (unknown|passengerCar..tram|agricultural)`` of
  ``ObjectClass.vehicleSubClass`` is written as its PER effective constraint ``(0..14)``
  (X.691 clause 10.3: the smallest range containing the union);
* the ``WITH COMPONENTS {..., protocolVersion (2), messageId (cpm)}`` inner subtype of the
  header is not PER-visible (X.691 B.2.2) and is not written; the encoder sets 2 and 14.

A message from another station that uses components this subset does not define (acceleration,
polar velocity, dimensions, a shape other than a polygon, ...) does not decode with this module; every message
footprint-uq sends decodes with the full standard's module.
"""

from __future__ import annotations

__all__ = ["CPM_ASN1", "CPM_ASN1_BY_CDD", "CDD_RELEASES", "DEFAULT_CDD", "VRU_SUBPROFILES", "CPM_PROTOCOL_VERSION",
           "MESSAGE_ID_CPM", "CONTAINER_ID_RSU", "CONTAINER_ID_SENSOR_INFORMATION", "CONTAINER_ID_PERCEPTION_REGION",
           "CONTAINER_ID_PERCEIVED_OBJECTS", "SENSOR_TYPE_MONOVIDEO"]

#: ItsPduHeader.protocolVersion of a TS 103 324 Release 2 CPM
CPM_PROTOCOL_VERSION = 2
#: MessageId of the CPM (CDD ``MessageId``: cpm (14))
MESSAGE_ID_CPM = 14
#: CpmContainerId values (TS 103 324 ``CPM-PDU-Descriptions``: ``originatingRsuContainer``,
#: ``sensorInformationContainer``, ``perceptionRegionContainer``, ``perceivedObjectContainer``)
CONTAINER_ID_RSU = 2
CONTAINER_ID_SENSOR_INFORMATION = 3
CONTAINER_ID_PERCEPTION_REGION = 4
CONTAINER_ID_PERCEIVED_OBJECTS = 5
#: CDD ``SensorType`` monovideo (a single camera)
SENSOR_TYPE_MONOVIDEO = 3

#: the CDD releases the subset is written for; the newest is the default
CDD_RELEASES = ("2.1.1", "2.2.1")
DEFAULT_CDD = "2.2.1"

#: VruProfileAndSubprofile alternatives (in CHOICE order) and their sub-profile names, numbers 0.. in order
#: (CDD V2.1.1: ENUMERATED with a last ``max (15)``; V2.2.1: INTEGER (0..15) with these named numbers; the
#: V2.2.1 bicyclist's ``roadbike (9)``, ``childrensbike (10)`` are not used)
VRU_SUBPROFILES = {
    "pedestrian": ("unavailable", "ordinary-pedestrian", "road-worker", "first-responder"),
    "bicyclistAndLightVruVehicle": ("unavailable", "bicyclist", "wheelchair-user", "horse-and-rider", "rollerskater",
                                    "e-scooter", "personal-transporter", "pedelec", "speed-pedelec"),
    "motorcyclist": ("unavailable", "moped", "motorcycle", "motorcycle-and-sidecar-right",
                     "motorcycle-and-sidecar-left"),
    "animal": ("unavailable", "wild-animal", "farm-animal", "service-animal"),
}
_VRU_TYPES = {"pedestrian": "VruSubProfilePedestrian", "bicyclistAndLightVruVehicle": "VruSubProfileBicyclist",
              "motorcyclist": "VruSubProfileMotorcyclist", "animal": "VruSubProfileAnimal"}

_TEMPLATE = r"""
FootprintUQ-CPM-Subset DEFINITIONS AUTOMATIC TAGS ::= BEGIN

-- placeholder of a component or alternative footprint-uq never sends (see the module doc)
NotSent ::= NULL

-- TS 103 324 CPM-PDU-Descriptions
CollectivePerceptionMessage ::= SEQUENCE {
    header   ItsPduHeader,
    payload  CpmPayload
}

CpmPayload ::= SEQUENCE {
    managementContainer  ManagementContainer,
    cpmContainers        WrappedCpmContainers,
    ...
}

ManagementContainer ::= SEQUENCE {
    referenceTime      TimestampIts,
    referencePosition  ReferencePosition,
    segmentationInfo   MessageSegmentationInfo OPTIONAL,
    messageRateRange   NotSent OPTIONAL,
    ...
}

CpmContainerId ::= INTEGER (1..16)

WrappedCpmContainer ::= SEQUENCE {
    containerId    CpmContainerId,
    containerData  OCTET STRING
}

WrappedCpmContainers ::= SEQUENCE SIZE (1..8, ...) OF WrappedCpmContainer

-- TS 103 324 CPM-OriginatingStationContainers
OriginatingRsuContainer ::= SEQUENCE {
    mapReference  NotSent OPTIONAL,
    ...
}

-- TS 103 324 CPM-SensorInformationContainer
SensorInformationContainer ::= SEQUENCE SIZE (1..128, ...) OF SensorInformation

SensorInformation ::= SEQUENCE {
    sensorId                    Identifier1B,
    sensorType                  SensorType,
    perceptionRegionShape       Shape OPTIONAL,
    perceptionRegionConfidence  ConfidenceLevel OPTIONAL,
    shadowingApplies            BOOLEAN,
    ...
}

-- TS 103 324 CPM-PerceptionRegionContainer
PerceptionRegionContainer ::= SEQUENCE SIZE (1..256, ...) OF PerceptionRegion

PerceptionRegion ::= SEQUENCE {
    measurementDeltaTime        DeltaTimeMilliSecondSigned,
    perceptionRegionConfidence  ConfidenceLevel,
    perceptionRegionShape       Shape,
    shadowingApplies            BOOLEAN,
    sensorIdList                SequenceOfIdentifier1B OPTIONAL,
    numberOfPerceivedObjects    CardinalNumber1B OPTIONAL,
    perceivedObjectIds          PerceivedObjectIds OPTIONAL,
    ...
}

PerceivedObjectIds ::= SEQUENCE SIZE (0..255, ...) OF Identifier2B

-- TS 103 324 CPM-PerceivedObjectContainer
PerceivedObjectContainer ::= SEQUENCE {
    numberOfPerceivedObjects  CardinalNumber1B,
    perceivedObjects          PerceivedObjects,
    ...
}

PerceivedObjects ::= SEQUENCE SIZE (0..255, ...) OF PerceivedObject

-- TS 102 894-2 ETSI-ITS-CDD
ItsPduHeader ::= SEQUENCE {
    protocolVersion  OrdinalNumber1B,
    messageId        MessageId,
    stationId        StationId
}

OrdinalNumber1B ::= INTEGER (0..255)
CardinalNumber1B ::= INTEGER (0..255)
MessageId ::= INTEGER (0..255)
StationId ::= INTEGER (0..4294967295)
Identifier1B ::= INTEGER (0..255)
SequenceOfIdentifier1B ::= SEQUENCE SIZE (1..128, ...) OF Identifier1B
ObjectPerceptionQuality ::= INTEGER (0..15)
SensorType ::= INTEGER (0..31)
StandardLength12b ::= INTEGER (0..4095)

MessageSegmentationInfo ::= SEQUENCE {
    totalMsgNo  CardinalNumber3b,
    thisMsgNo   OrdinalNumber3b
}

CardinalNumber3b ::= INTEGER (1..8)
OrdinalNumber3b ::= INTEGER (1..8)

Shape ::= CHOICE {
    rectangular   NotSent,
    circular      NotSent,
    polygonal     PolygonalShape,
    elliptical    NotSent,
    radial        NotSent,
    radialShapes  NotSent,
    ...
}

-- the standard's polygon is SequenceOfCartesianPosition3d (SIZE (1..16, ...)) constrained serially by
-- (SIZE (3..16, ...)): the effective constraint, written here, is SIZE (3..16, ...) (see the module doc)
PolygonalShape ::= SEQUENCE {
    shapeReferencePoint  CartesianPosition3d OPTIONAL,
    polygon              SEQUENCE (SIZE (3..16, ...)) OF CartesianPosition3d,
    height               StandardLength12b OPTIONAL
}

CartesianPosition3d ::= SEQUENCE {
    xCoordinate  CartesianCoordinate,
    yCoordinate  CartesianCoordinate,
    zCoordinate  CartesianCoordinate OPTIONAL
}

CartesianCoordinate ::= INTEGER (-32768..32767)
TimestampIts ::= INTEGER (0..4398046511103)

ReferencePosition ::= SEQUENCE {
    latitude                   Latitude,
    longitude                  Longitude,
    positionConfidenceEllipse  PosConfidenceEllipse,
    altitude                   Altitude
}

Latitude ::= INTEGER (-900000000..900000001)
Longitude ::= INTEGER (-1800000000..1800000001)

PosConfidenceEllipse ::= SEQUENCE {
    semiMajorConfidence   SemiAxisLength,
    semiMinorConfidence   SemiAxisLength,
    semiMajorOrientation  HeadingValue
}

SemiAxisLength ::= INTEGER (0..4095)
HeadingValue ::= INTEGER (0..3601)

Altitude ::= SEQUENCE {
    altitudeValue       AltitudeValue,
    altitudeConfidence  AltitudeConfidence
}

AltitudeValue ::= INTEGER (-100000..800001)

AltitudeConfidence ::= ENUMERATED {
    alt-000-01 (0), alt-000-02 (1), alt-000-05 (2), alt-000-10 (3), alt-000-20 (4), alt-000-50 (5),
    alt-001-00 (6), alt-002-00 (7), alt-005-00 (8), alt-010-00 (9), alt-020-00 (10), alt-050-00 (11),
    alt-100-00 (12), alt-200-00 (13), outOfRange (14), unavailable (15)
}

PerceivedObject ::= SEQUENCE {
    objectId                            Identifier2B OPTIONAL,
    measurementDeltaTime                DeltaTimeMilliSecondSigned,
    position                            CartesianPosition3dWithConfidence,
    velocity                            Velocity3dWithConfidence OPTIONAL,
    acceleration                        NotSent OPTIONAL,
    angles                              EulerAnglesWithConfidence OPTIONAL,
    zAngularVelocity                    NotSent OPTIONAL,
    lowerTriangularCorrelationMatrices  LowerTriangularPositiveSemidefiniteMatrices OPTIONAL,
    objectDimensionZ                    NotSent OPTIONAL,
    objectDimensionY                    NotSent OPTIONAL,
    objectDimensionX                    NotSent OPTIONAL,
    objectAge                           DeltaTimeMilliSecondSigned (0..2047) OPTIONAL,
    objectPerceptionQuality             ObjectPerceptionQuality OPTIONAL,
    sensorIdList                        SequenceOfIdentifier1B OPTIONAL,
    classification                      ObjectClassDescription OPTIONAL,
    mapPosition                         NotSent OPTIONAL,
    ...
}

Identifier2B ::= INTEGER (0..65535)
DeltaTimeMilliSecondSigned ::= INTEGER (-2048..2047)

CartesianPosition3dWithConfidence ::= SEQUENCE {
    xCoordinate  CartesianCoordinateWithConfidence,
    yCoordinate  CartesianCoordinateWithConfidence,
    zCoordinate  CartesianCoordinateWithConfidence OPTIONAL
}

CartesianCoordinateWithConfidence ::= SEQUENCE {
    value       CartesianCoordinateLarge,
    confidence  CoordinateConfidence
}

CartesianCoordinateLarge ::= INTEGER (-131072..131071)

Velocity3dWithConfidence ::= CHOICE {
    polarVelocity      NotSent,
    cartesianVelocity  VelocityCartesian
}

VelocityCartesian ::= SEQUENCE {
    xVelocity  VelocityComponent,
    yVelocity  VelocityComponent,
    zVelocity  VelocityComponent OPTIONAL
}

VelocityComponent ::= SEQUENCE {
    value       VelocityComponentValue,
    confidence  SpeedConfidence
}

VelocityComponentValue ::= INTEGER (-16383..16383)
SpeedConfidence ::= INTEGER (1..127)

EulerAnglesWithConfidence ::= SEQUENCE {
    zAngle  CartesianAngle,
    yAngle  CartesianAngle OPTIONAL,
    xAngle  CartesianAngle OPTIONAL
}

CartesianAngle ::= SEQUENCE {
    value       CartesianAngleValue,
    confidence  AngleConfidence
}

CartesianAngleValue ::= INTEGER (0..3601)
AngleConfidence ::= INTEGER (1..127)
CoordinateConfidence ::= INTEGER (1..4096)

LowerTriangularPositiveSemidefiniteMatrices ::= SEQUENCE SIZE (1..4) OF LowerTriangularPositiveSemidefiniteMatrix

LowerTriangularPositiveSemidefiniteMatrix ::= SEQUENCE {
    componentsIncludedIntheMatrix  MatrixIncludedComponents,
    matrix                         LowerTriangularPositiveSemidefiniteMatrixColumns
}

MatrixIncludedComponents ::= BIT STRING {
    xPosition (0), yPosition (1), zPosition (2), xVelocityOrVelocityMagnitude (3),
    yVelocityOrVelocityDirection (4), zSpeed (5), xAccelOrAccelMagnitude (6), yAccelOrAccelDirection (7),
    zAcceleration (8), zAngle (9), yAngle (10), xAngle (11), zAngularVelocity (12)
} (SIZE (13, ...))

LowerTriangularPositiveSemidefiniteMatrixColumns ::= SEQUENCE SIZE (@COLUMNS@) OF CorrelationColumn
CorrelationColumn ::= SEQUENCE SIZE (1..13, ...) OF CorrelationCellValue
CorrelationCellValue ::= INTEGER (-100..101)

ObjectClassDescription ::= SEQUENCE SIZE (1..8) OF ObjectClassWithConfidence

ObjectClassWithConfidence ::= SEQUENCE {
    objectClass  ObjectClass,
    confidence   ConfidenceLevel
}

ObjectClass ::= CHOICE {
    vehicleSubClass  TrafficParticipantType (0..14),
    vruSubClass      VruProfileAndSubprofile,
    groupSubClass    NotSent,
    otherSubClass    OtherSubClass,
    ...
}

TrafficParticipantType ::= INTEGER (0..255)

VruProfileAndSubprofile ::= CHOICE {
    pedestrian                   VruSubProfilePedestrian,
    bicyclistAndLightVruVehicle  VruSubProfileBicyclist,
    motorcyclist                 VruSubProfileMotorcyclist,
    animal                       VruSubProfileAnimal,
    ...
}

@VRU@
OtherSubClass ::= INTEGER (0..255)
ConfidenceLevel ::= INTEGER (1..101)

END
"""


def _vru_types(cdd: str) -> str:
    out = []
    for alt, names in VRU_SUBPROFILES.items():
        if cdd == "2.1.1":
            body = ", ".join(f"{n} ({i})" for i, n in enumerate(names)) + ", max (15)"
            out.append(f"{_VRU_TYPES[alt]} ::= ENUMERATED {{ {body} }}")
        else:
            out.append(f"{_VRU_TYPES[alt]} ::= INTEGER (0..15)")
    return "\n".join(out)


def _module(cdd: str) -> str:
    return (_TEMPLATE.replace("@COLUMNS@", "1..13" if cdd == "2.1.1" else "1..13, ...")
            .replace("@VRU@", _vru_types(cdd)))


#: the subset module of each CDD release (:data:`CDD_RELEASES`)
CPM_ASN1_BY_CDD = {cdd: _module(cdd) for cdd in CDD_RELEASES}
#: the subset module of CDD V2.1.1 (the first release; kept under its old name)
CPM_ASN1 = CPM_ASN1_BY_CDD["2.1.1"]
