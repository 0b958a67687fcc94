"""orokit.metrics"""
