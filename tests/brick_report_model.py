"""A small Brick model the Brick report has something to say about: an official class graphtwin
does not model (``brick:Chiller``), a misspelt one (``brick:Supply_Air_Temprature_Setpoint``), a
relation no rule reads (``brick:regulates``) and a point without a unit (``:sat``)."""

REPORT_NAMESPACE = "https://example.org/report#"
REPORT_MODEL = """
@prefix brick: <https://brickschema.org/schema/Brick#> .
@prefix unit:  <http://qudt.org/vocab/unit/> .
@prefix :      <https://example.org/report#> .
:ahu a brick:Air_Handling_Unit ; brick:hasPart :fan, :chiller ; brick:hasPoint :sat .
:fan a brick:Supply_Fan ; brick:regulates :sat .
:chiller a brick:Chiller .
:sat a brick:Supply_Air_Temperature_Sensor .
:sp a brick:Supply_Air_Temprature_Setpoint ; brick:isPointOf :ahu .
"""
