"""orokit.classify"""
