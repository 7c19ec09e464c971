"""Coaty (communication protocol version 3) bridge for shared obstacles.

Modules: ``errors`` (exception tree), ``topics`` (topic names), ``compact``
(index encoding), ``codec`` (JSON <-> validated values; no paho, no rospy),
``client`` (paho-mqtt agent), ``broker`` (mosquitto helper), ``node`` (rospy).
"""
